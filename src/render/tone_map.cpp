#include "render/tone_map.h"

#include <cstdlib>
#include <iterator>

namespace rf {
namespace {

// The smallest float d in [0, 1] with encode_srgb8_exact(d) >= code, by
// bisection over the float bit patterns (ordered like the values for d >= 0).
float first_display_with_code(uint32_t code) {
    uint32_t lo = 0, hi = 0x3f800000u;  // bits of 0.0f and 1.0f; the code of 1.0f is 255
    const auto value = [](uint32_t bits) {
        float f;
        static_assert(sizeof f == sizeof bits);
        __builtin_memcpy(&f, &bits, sizeof f);
        return f;
    };
    while (lo < hi) {
        const uint32_t mid = lo + (hi - lo) / 2;
        if (encode_srgb8_exact(value(mid)) >= code) hi = mid;
        else lo = mid + 1;
    }
    return value(lo);
}

Srgb8Thresholds make_thresholds() {
    Srgb8Thresholds t{};
    for (uint32_t code = 1; code <= 255; ++code) t.at[code - 1] = first_display_with_code(code);
    uint32_t code = 0;  // thresholds at or below the bucket's first value
    for (uint32_t bucket = 0; bucket < std::size(t.first_code); ++bucket) {
        float first;
        const uint32_t bits = bucket << Srgb8Thresholds::kBucketShift;
        __builtin_memcpy(&first, &bits, sizeof first);
        while (code < 255 && t.at[code] <= first) ++code;
        t.first_code[bucket] = uint8_t(code);
        // The lookup adds at most one step within a bucket: two would be a bug here.
        float last;
        const uint32_t last_bits = bits | ((1u << Srgb8Thresholds::kBucketShift) - 1u);
        __builtin_memcpy(&last, &last_bits, sizeof last);
        if (code + 1 < 255 && t.at[code + 1] <= last) std::abort();
    }
    return t;
}

}  // namespace

const Srgb8Thresholds& srgb8_thresholds() {
    static const Srgb8Thresholds table = make_thresholds();
    return table;
}

}  // namespace rf

// The public entry points of rayforge/render/tone_mapping.h.
namespace rf {

Vec3f apply_tone_curve(Vec3f color, ToneCurve curve) { return tone_curve(color, curve); }

void tone_map_srgb8(Vec3f radiance, const ToneMapping& tone, uint8_t out[3]) { tone_map_pixel(radiance, tone, out); }

}  // namespace rf
