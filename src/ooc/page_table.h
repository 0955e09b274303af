// The page table of one page manager, as the per-ray code sees it (the
// dissertation's GPU data manager, Garanzha 2014, §6.2): one 32-bit
// descriptor per page and a pool of equal slots holding the cached pages.
//
//   bits 0-23  slot of the page in the pool (valid when !OOC)
//   bits 24-28 TimeUsed: how often it was used, saturating at 31 (LFU key)
//   bit 29     WasRead: cached during an earlier iteration of the current
//              query loop, so every ray has already searched it
//   bit 30     Requested: used (cached) or asked for (not cached) this iteration
//   bit 31     OOC: not in the cache
//
// A ray marks a page it uses or needs with one atomic OR of Requested (only
// when the bit is not yet set, so a popular page costs one read); TimeUsed is
// counted from Requested by the manager between iterations, not by the
// rays (the safe reading of Garanzha 2014, §6.2). Written once for
// both backends (host atomics / CUDA atomics).
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"

namespace rf::pack {

inline constexpr uint32_t kSlotMask = 0x00FFFFFFu;
inline constexpr uint32_t kTimeShift = 24;
inline constexpr uint32_t kTimeMask = 0x1Fu << kTimeShift;
inline constexpr uint32_t kTimeMax = 31;
inline constexpr uint32_t kWasRead = 1u << 29;
inline constexpr uint32_t kRequested = 1u << 30;
inline constexpr uint32_t kOutOfCore = 1u << 31;
inline constexpr uint32_t kMaxSlots = kSlotMask;  // slot kSlotMask is never used

RF_HDI uint32_t load_descriptor(const uint32_t* d) {
#if defined(__CUDA_ARCH__)
    return *(const volatile uint32_t*)d;
#else
    return __atomic_load_n(d, __ATOMIC_RELAXED);
#endif
}

RF_HDI void or_descriptor(uint32_t* d, uint32_t bits) {
#if defined(__CUDA_ARCH__)
    atomicOr(d, bits);
#else
    __atomic_fetch_or(d, bits, __ATOMIC_RELAXED);
#endif
}

struct PageTableView {
    uint32_t* descriptors = nullptr;  // one per page
    uint8_t* slots = nullptr;         // slot_bytes per slot
    uint64_t slot_bytes = 0;
    uint32_t page_count = 0;

    [[nodiscard]] RF_HDI uint32_t descriptor(uint32_t page) const { return load_descriptor(&descriptors[page]); }
    // The page's bytes, or nullptr when it is not cached.
    [[nodiscard]] RF_HDI const uint8_t* cached(uint32_t page) const {
        const uint32_t d = descriptor(page);
        return (d & kOutOfCore) ? nullptr : slots + uint64_t(d & kSlotMask) * slot_bytes;
    }
    [[nodiscard]] RF_HDI bool was_read(uint32_t page) const { return (descriptor(page) & kWasRead) != 0; }
    // Marks a use of a cached page, or a request for a missing one.
    RF_HDI void request(uint32_t page) const {
        if (!(descriptor(page) & kRequested)) or_descriptor(&descriptors[page], kRequested);
    }
};

}  // namespace rf::pack
