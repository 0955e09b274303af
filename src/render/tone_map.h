// Per-pixel tone mapping shared by PNG output, the CPU display image and the
// CUDA display kernel: exposure, the curve (rayforge/render/tone_mapping.h),
// then the 8-bit sRGB code. On the host the sRGB code is read from a table
// of the 255 display values where the code steps up, found once by
// bisection on the exact encoding, so it equals lround(linear_to_srgb(d) *
// 255) for every float d (a test compares them) with one bucket lookup and
// one comparison instead of powf (several times cheaper; docs/viewer.md has
// the measurement); the device computes the encoding directly.
#pragma once

#include <cmath>
#include <cstdint>

#include "math/color.h"
#include "rayforge/core/host_device.h"
#include "rayforge/render/tone_mapping.h"

namespace rf {

// NaN and negatives (from filtering or a broken sample) are black; +inf is
// replaced by a huge finite value so the curves treat it as very bright.
RF_HDI float tone_sanitize(float v) {
    if (!(v > 0.0f)) return 0.0f;  // also NaN
    return fminf(v, 1e30f);
}

// Narkowicz's fit; 2.51 / 2.43 > 1, so it reaches 1 at a finite input (about
// 7.24) and the clamp makes it saturate there.
RF_HDI float aces_narkowicz(float x) {
    x = fminf(x, 100.0f);  // already 1 there; keeps x * x from overflowing to inf / inf
    const float mapped = (x * (2.51f * x + 0.03f)) / (x * (2.43f * x + 0.59f) + 0.14f);
    return fminf(fmaxf(mapped, 0.0f), 1.0f);
}

RF_HDI Vec3f tone_curve(Vec3f color, ToneCurve curve) {
    const Vec3f c(tone_sanitize(color.x), tone_sanitize(color.y), tone_sanitize(color.z));
    switch (curve) {
        case ToneCurve::Clamp: break;
        case ToneCurve::Reinhard: {
            const float l = luminance(c);
            if (!(l > 0.0f)) return Vec3f(0.0f);  // pure black (a pure blue of tiny luminance still has l > 0)
            const Vec3f scaled = c * (1.0f / (1.0f + l));  // = c * (l / (1 + l)) / l
            return {fminf(scaled.x, 1.0f), fminf(scaled.y, 1.0f), fminf(scaled.z, 1.0f)};
        }
        case ToneCurve::Aces: return {aces_narkowicz(c.x), aces_narkowicz(c.y), aces_narkowicz(c.z)};
    }
    return {fminf(c.x, 1.0f), fminf(c.y, 1.0f), fminf(c.z, 1.0f)};
}

// Display value in [0, 1] -> 8-bit sRGB code, computed.
RF_HDI uint8_t encode_srgb8_exact(float display) {
    return uint8_t(lroundf(linear_to_srgb(display) * 255.0f));
}

#if !defined(__CUDA_ARCH__)
// at[k - 1] = the smallest display value whose code is >= k; first_code[b] =
// the code of the smallest float whose bits >> 16 are b. The codes step up
// at most once within such a bucket (checked when the table is made), so a
// bucket and one comparison give the code.
struct Srgb8Thresholds {
    static constexpr uint32_t kBucketShift = 16;
    float at[255];
    uint8_t first_code[(0x3f800000u >> kBucketShift) + 1];  // up to 1.0f
};
const Srgb8Thresholds& srgb8_thresholds();  // tone_map.cpp

inline uint8_t encode_srgb8_table(float display) {
    if (!(display > 0.0f)) return 0;
    if (display >= 1.0f) return 255;
    const Srgb8Thresholds& t = srgb8_thresholds();
    uint32_t bits;
    __builtin_memcpy(&bits, &display, sizeof bits);
    const uint32_t code = t.first_code[bits >> Srgb8Thresholds::kBucketShift];
    return uint8_t(code + (code < 255 && display >= t.at[code] ? 1u : 0u));
}
#endif

RF_HDI uint8_t encode_srgb8(float display) {
#if defined(__CUDA_ARCH__)
    return encode_srgb8_exact(display);
#else
    return encode_srgb8_table(display);
#endif
}

// One pixel as PNG output and the display images write it.
RF_HDI void tone_map_pixel(Vec3f radiance, ToneMapping tone, uint8_t out[3]) {
    const Vec3f display = tone_curve(radiance * tone.exposure, tone.curve);
    out[0] = encode_srgb8(display.x);
    out[1] = encode_srgb8(display.y);
    out[2] = encode_srgb8(display.z);
}

}  // namespace rf
