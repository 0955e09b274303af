// Ray sort keys (Garanzha and Loop 2010, "Fast Ray Sorting and
// Breadth-First Packet Traversal for GPU Ray Tracing", sec. 3): a ray is
// hashed to a 32-bit key made of its quantised origin and its quantised
// direction, so that sorting rays by key brings together rays that start
// close to each other and go the same way, which then visit the same nodes
// and triangles (coherent memory access, less divergence on the GPU).
//
// Bit split, high to low:
//   bits 31..14  origin: the cell of a 64^3 grid over `bounds`, as an 18-bit
//                Morton code (6 bits per axis, interleaved), so that nearby
//                cells get nearby keys;
//   bits 13..0   direction: the cell of a 128 x 128 grid over the octahedral
//                map of the unit sphere, as a 14-bit Morton code (7 bits per
//                axis).
// Origin first: secondary rays leave many points in many directions, and a
// shared origin cell is the stronger predictor of shared traversal. Origins
// outside `bounds` are clamped to its border cells.
//
// The paper also compresses runs of equal keys before sorting; on the CPU the
// (key, index) pairs are sorted directly.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"

namespace rf {

inline constexpr int kRayKeyOriginBitsPerAxis = 6;
inline constexpr int kRayKeyDirectionBitsPerAxis = 7;
inline constexpr int kRayKeyDirectionBits = 2 * kRayKeyDirectionBitsPerAxis;  // 14

// The low 6 bits of v moved to bits 0, 3, 6, ... 15.
RF_HDI uint32_t spread_bits_by_3(uint32_t v) {
    uint32_t r = 0;
    for (int i = 0; i < kRayKeyOriginBitsPerAxis; ++i) r |= ((v >> i) & 1u) << (3 * i);
    return r;
}

// The low 7 bits of v moved to bits 0, 2, 4, ... 12.
RF_HDI uint32_t spread_bits_by_2(uint32_t v) {
    uint32_t r = 0;
    for (int i = 0; i < kRayKeyDirectionBitsPerAxis; ++i) r |= ((v >> i) & 1u) << (2 * i);
    return r;
}

// x in [0, 1] to a cell in [0, cells); NaN goes to cell 0.
RF_HDI uint32_t quantise_unit(float x, int cells) {
    const float scaled = fminf(fmaxf(x * float(cells), 0.0f), float(cells - 1));
    return uint32_t(scaled);
}

// The octahedral map of a direction (any length but 0) onto [0, 1]^2: the
// upper hemisphere covers the inner diamond, the lower one the four corners.
RF_HDI Vec2f octahedral_unit_square(Vec3f d) {
    const float l1 = fabsf(d.x) + fabsf(d.y) + fabsf(d.z);
    if (!(l1 > 0.0f)) return {0.0f, 0.0f};
    float u = d.x / l1, v = d.y / l1;
    if (d.z < 0.0f) {
        const float fu = (1.0f - fabsf(v)) * (u >= 0.0f ? 1.0f : -1.0f);
        const float fv = (1.0f - fabsf(u)) * (v >= 0.0f ? 1.0f : -1.0f);
        u = fu;
        v = fv;
    }
    return {0.5f * u + 0.5f, 0.5f * v + 0.5f};
}

RF_HDI uint32_t ray_sort_key(const Ray& ray, const Box3f& bounds) {
    constexpr int origin_cells = 1 << kRayKeyOriginBitsPerAxis;
    constexpr int direction_cells = 1 << kRayKeyDirectionBitsPerAxis;
    const Vec3f extent = bounds.hi - bounds.lo;
    const Vec3f rel = ray.org - bounds.lo;
    // A flat box (extent 0 on an axis) puts every origin in cell 0 of that axis.
    const uint32_t ox = quantise_unit(extent.x > 0.0f ? rel.x / extent.x : 0.0f, origin_cells);
    const uint32_t oy = quantise_unit(extent.y > 0.0f ? rel.y / extent.y : 0.0f, origin_cells);
    const uint32_t oz = quantise_unit(extent.z > 0.0f ? rel.z / extent.z : 0.0f, origin_cells);
    const uint32_t origin = spread_bits_by_3(ox) << 2 | spread_bits_by_3(oy) << 1 | spread_bits_by_3(oz);
    const Vec2f oct = octahedral_unit_square(ray.dir);
    const uint32_t du = quantise_unit(oct.x, direction_cells), dv = quantise_unit(oct.y, direction_cells);
    const uint32_t direction = spread_bits_by_2(du) << 1 | spread_bits_by_2(dv);
    return origin << kRayKeyDirectionBits | direction;
}

}  // namespace rf
