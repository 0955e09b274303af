// Transparent-huge-page hint for large arrays the builders write once, end
// to end: with 4 KiB pages the first-touch page faults cost about as much as
// filling the array (measured on the binned builder and the wide collapse).
// A hint only; no effect outside Linux or for arrays under 2 MiB.
#pragma once

#include <cstddef>
#include <cstdint>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace rf {

inline void hint_huge_pages(const void* data, size_t bytes) {
#if defined(__linux__)
    constexpr uintptr_t kHugePage = uintptr_t(2) << 20;
    const auto begin = reinterpret_cast<uintptr_t>(data);
    const uintptr_t lo = (begin + kHugePage - 1) & ~(kHugePage - 1);  // whole pages inside the array only
    const uintptr_t hi = (begin + bytes) & ~(kHugePage - 1);
    if (hi > lo) (void)madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
#else
    (void)data;
    (void)bytes;
#endif
}

}  // namespace rf
