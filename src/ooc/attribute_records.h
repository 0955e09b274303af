// The shading record of a paged triangle (§6.4): stored per triangle in the
// quads' Morton order, read back through the attribute page manager at
// shading time and turned into the rf::ShadingTriangle the integrators use.
// Full records are ShadingTriangles as they are; compact ones keep the
// normals and material and store uvs as half floats (|error| <= 2^-11
// relative), without the tangent and the uv/area ratio (so no normal maps
// and no mip selection by uv density). Decoding is shared host/device code.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "ooc/pack_format.h"
#include "render/shading_triangles.h"

namespace rf::pack {

// IEEE 754 binary16 <-> binary32, round to nearest even; NaN stays NaN,
// overflow becomes infinity.
RF_HDI uint16_t float_to_half(float f) {
    uint32_t x;
    memcpy(&x, &f, 4);
    const uint32_t sign = (x >> 16) & 0x8000u;
    const uint32_t abs = x & 0x7FFFFFFFu;
    if (abs >= 0x7F800000u) return uint16_t(sign | 0x7C00u | (abs > 0x7F800000u ? 0x200u : 0u));
    if (abs >= 0x477FF000u) return uint16_t(sign | 0x7C00u);  // rounds past the largest half
    if (abs < 0x38800000u) {  // below the smallest normal half: a subnormal one, m * 2^-24
        const int shift = 126 - int(abs >> 23);
        if (shift > 24) return uint16_t(sign);
        const uint32_t mant = (abs & 0x7FFFFFu) | 0x800000u;
        uint32_t r = mant >> shift;
        const uint32_t rest = mant & ((1u << shift) - 1u), halfway = 1u << (shift - 1);
        if (rest > halfway || (rest == halfway && (r & 1u))) ++r;
        return uint16_t(sign | r);
    }
    uint32_t r = ((abs - 0x38000000u) >> 13);
    const uint32_t rest = abs & 0x1FFFu;
    if (rest > 0x1000u || (rest == 0x1000u && (r & 1u))) ++r;
    return uint16_t(sign | r);
}

RF_HDI float half_to_float(uint16_t h) {
    const uint32_t sign = uint32_t(h & 0x8000u) << 16;
    const uint32_t exp = (h >> 10) & 0x1Fu, mant = h & 0x3FFu;
    uint32_t x;
    if (exp == 0) {
        const float v = float(mant) * (1.0f / 16777216.0f);  // mant * 2^-24
        memcpy(&x, &v, 4);
        x |= sign;
    } else if (exp == 31) {
        x = sign | 0x7F800000u | (mant << 13);
    } else {
        x = sign | ((exp + 112u) << 23) | (mant << 13);
    }
    float f;
    memcpy(&f, &x, 4);
    return f;
}

// The record of one triangle in `format`, written to `out` (attribute_record_bytes(format) bytes).
inline void encode_attribute_record(const ShadingTriangle& t, AttributeFormat format, uint8_t* out) {
    if (format == AttributeFormat::Full) {
        memcpy(out, &t, sizeof(ShadingTriangle));
        return;
    }
    CompactShading c;
    c.geometric_normal = encode_octahedral(t.geometric_normal);
    c.material_flags = (t.material & 0xFFFFFFu) | ((t.flags & (kHasNormals | kHasUvs)) << 24);
    for (int k = 0; k < 3; ++k) {
        c.normals[k] = t.normals[k];
        c.uv[k][0] = float_to_half(t.uv[k].x);
        c.uv[k][1] = float_to_half(t.uv[k].y);
    }
    memcpy(out, &c, sizeof(c));
}

RF_HDI ShadingTriangle decode_attribute_record(const uint8_t* in, AttributeFormat format) {
    ShadingTriangle t;
    if (format == AttributeFormat::Full) {
        memcpy(&t, in, sizeof(ShadingTriangle));
        return t;
    }
    CompactShading c;
    memcpy(&c, in, sizeof(c));
    t.geometric_normal = decode_octahedral(c.geometric_normal);
    t.material = c.material_flags & 0xFFFFFFu;
    t.flags = c.material_flags >> 24;
    for (int k = 0; k < 3; ++k) {
        t.normals[k] = c.normals[k];
        t.uv[k] = Vec2f{half_to_float(c.uv[k][0]), half_to_float(c.uv[k][1])};
    }
    return t;
}

}  // namespace rf::pack
