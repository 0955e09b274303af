// Morton (Z-order) codes for the Morton-ordered BVH builders (LBVH, HLBVH2,
// PLOC): 30-bit codes (10 bits per axis) as in Karras 2012 and Garanzha's
// HLBVH2, 63-bit codes (21 bits per axis) for finer ordering. The encoders
// are RF_HDI so that a CUDA builder can reuse them unchanged.
//
// Bit layout: x takes the highest bit of every 3-bit group, then y, then z,
// i.e. code = ... x1 y1 z1 x0 y0 z0.
#pragma once

#include <cstdint>

#if defined(__BMI2__) && !defined(__CUDA_ARCH__)
#include <immintrin.h>
#define RF_MORTON_PDEP 1
#endif

#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf {

// Spreads the low 10 bits of v so that bit i moves to bit 3i.
RF_HDI uint32_t morton_expand_10(uint32_t v) {
#ifdef RF_MORTON_PDEP
    return _pdep_u32(v, 0x09249249u);  // one instruction where BMI2 is compiled in
#else
    v &= 0x3ffu;
    v = (v | (v << 16)) & 0x030000ffu;
    v = (v | (v << 8)) & 0x0300f00fu;
    v = (v | (v << 4)) & 0x030c30c3u;
    v = (v | (v << 2)) & 0x09249249u;
    return v;
#endif
}

// Spreads the low 21 bits of v so that bit i moves to bit 3i.
RF_HDI uint64_t morton_expand_21(uint64_t v) {
#ifdef RF_MORTON_PDEP
    return _pdep_u64(v, 0x1249249249249249ull);
#else
    v &= 0x1fffffull;
    v = (v | (v << 32)) & 0x001f00000000ffffull;
    v = (v | (v << 16)) & 0x001f0000ff0000ffull;
    v = (v | (v << 8)) & 0x100f00f00f00f00full;
    v = (v | (v << 4)) & 0x10c30c30c30c30c3ull;
    v = (v | (v << 2)) & 0x1249249249249249ull;
    return v;
#endif
}

// 30-bit code of cell (x, y, z), each in [0, 1024).
RF_HDI uint32_t morton_encode_30(uint32_t x, uint32_t y, uint32_t z) {
    return (morton_expand_10(x) << 2) | (morton_expand_10(y) << 1) | morton_expand_10(z);
}

// 63-bit code of cell (x, y, z), each in [0, 2^21).
RF_HDI uint64_t morton_encode_63(uint64_t x, uint64_t y, uint64_t z) {
    return (morton_expand_21(x) << 2) | (morton_expand_21(y) << 1) | morton_expand_21(z);
}

// Maps points of a box onto a 2^bits_per_axis grid. Axes along which the box
// is flat map to cell 0; points outside (or NaN) clamp to the border cells.
struct MortonQuantizer {
    Vec3f origin;
    Vec3f scale;  // cells per unit length
    float max_cell;

    RF_HDI MortonQuantizer(const Box3f& box, int bits_per_axis) : origin(box.lo) {
        const float cells = static_cast<float>(1u << bits_per_axis);
        max_cell = cells - 1.0f;
        const Vec3f extent = box.extent();
        for (int axis = 0; axis < 3; ++axis) {
            const float s = cells / extent[axis];
            scale[axis] = (extent[axis] > 0.0f && s < 3.0e38f) ? s : 0.0f;
        }
    }
    RF_HDI uint32_t cell(float v, int axis) const {
        float x = (v - origin[axis]) * scale[axis];
        x = x > 0.0f ? x : 0.0f;  // also maps NaN to 0
        x = x < max_cell ? x : max_cell;
        return static_cast<uint32_t>(x);
    }
    RF_HDI uint32_t code30(const Vec3f& p) const { return morton_encode_30(cell(p.x, 0), cell(p.y, 1), cell(p.z, 2)); }
    RF_HDI uint64_t code63(const Vec3f& p) const { return morton_encode_63(cell(p.x, 0), cell(p.y, 1), cell(p.z, 2)); }
};

}  // namespace rf
