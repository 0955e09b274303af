// Helpers shared by the SAH builders (binned, full sweep, SBVH) and the
// reinsertion optimizer: fast box growth, sortable float keys and a
// parallel merge sort. Their common top-down recursion is top_down_sah.h.
#pragma once

#include <algorithm>
#include <bit>
#include <cstdint>
#include <vector>

#include "core/parallel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/memory_budget.h"

namespace rf::sweep {

// std::min/max compile to single instructions (the NaN-aware fminf/fmaxf
// behind Box3f::extend are library calls); builder inputs are finite.
inline Vec3f vmin(const Vec3f& a, const Vec3f& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f vmax(const Vec3f& a, const Vec3f& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline void grow(Box3f& box, const Vec3f& lo, const Vec3f& hi) {
    box.lo = vmin(box.lo, lo);
    box.hi = vmax(box.hi, hi);
}
inline void grow(Box3f& box, const Box3f& b) { grow(box, b.lo, b.hi); }

// Maps a float to an unsigned integer with the same order (-0 just below +0),
// so that sorting (key << 32 | index) sorts by value with a total tie-break.
inline uint32_t sortable_key(float f) {
    const uint32_t bits = std::bit_cast<uint32_t>(f);
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}
inline uint64_t sort_key(float value, uint32_t index) {
    return (uint64_t{sortable_key(value)} << 32) | index;
}

// Merge sort of data[0, n) on TBB tasks (via core/parallel.h); tmp has room
// for n values. Small ranges fall back to std::sort.
inline void parallel_sort(uint64_t* data, uint64_t* tmp, size_t n) {
    constexpr size_t kSerialSize = 32 * 1024;
    if (n <= kSerialSize) {
        std::sort(data, data + n);
        return;
    }
    const size_t half = n / 2;
    parallel::invoke([&] { parallel_sort(data, tmp, half); },
                     [&] { parallel_sort(data + half, tmp + half, n - half); });
    std::merge(data, data + half, data + half, data + n, tmp);
    std::copy(tmp, tmp + n, data);
}

}  // namespace rf::sweep
