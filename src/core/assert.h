// RF_ASSERT(condition, "what breaks"): an invariant the code relies on
// (indices in range, counts that must add up, queues that cannot overflow),
// checked where RAYFORGE_ASSERTIONS is defined: Debug and sanitizer builds
// (CMakeLists.txt), on the host and in CUDA kernels alike, and compiled out
// of Release builds. A failure is a bug, not bad input (bad input gets an
// rf::Error): it prints "FILE:LINE: assertion failed: CONDITION (what
// breaks)" and aborts (on the device: the thread traps, and the next CUDA
// call reports the launch failure).
#pragma once

#include "rayforge/core/host_device.h"

#if defined(RAYFORGE_ASSERTIONS)
#include <cstdio>
#include <cstdlib>

namespace rf::detail {

[[noreturn]] RF_HD inline void assertion_failed(const char* condition, const char* what, const char* file, int line) {
#if defined(__CUDA_ARCH__)
    printf("%s:%d: assertion failed: %s (%s)\n", file, line, condition, what);
    __trap();
#else
    std::fprintf(stderr, "%s:%d: assertion failed: %s (%s)\n", file, line, condition, what);
    std::abort();
#endif
}

}  // namespace rf::detail

#define RF_ASSERT(condition, what) \
    ((condition) ? (void)0 : ::rf::detail::assertion_failed(#condition, what, __FILE__, __LINE__))
#else
#define RF_ASSERT(condition, what) ((void)0)
#endif
