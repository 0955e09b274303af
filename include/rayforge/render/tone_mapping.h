// How scene-referred radiance becomes display values: an exposure scale, a
// tone curve, then the sRGB encoding. PNG output (rf::write_image) and the
// display images of rf::Renderer apply the same per-pixel code.
#pragma once

#include <cstdint>
#include <string>

#include "rayforge/math/vec.h"

namespace rf {

enum class ToneCurve : uint8_t {
    Clamp,     // clamp each channel to [0, 1]
    Reinhard,  // Reinhard et al. 2002 global operator L / (1 + L) on Rec. 709 luminance, hue kept
    Aces       // Narkowicz 2015 "ACES Filmic Tone Mapping Curve" fit, per channel (see apply_tone_curve)
};

struct ToneMapping {
    float exposure = 1.0f;  // linear scale applied before the curve
    ToneCurve curve = ToneCurve::Clamp;
};

// "clamp", "reinhard", "aces" (case-insensitive); rf::Error otherwise.
ToneCurve parse_tone_curve(const std::string& name);
std::string to_string(ToneCurve curve);

// The curve alone on an exposure-scaled linear color: display-linear values in
// [0, 1] (before the sRGB encoding). NaN and negative channels become 0 and
// +inf is treated as very bright. Reinhard scales rgb by L'/L, so a saturated
// color may leave channels above 1 that the clamp then cuts. ACES is the
// published rational fit (2.51x^2 + 0.03x) / (2.43x^2 + 0.59x + 0.14), without
// the 0.6 pre-exposure Narkowicz suggests (use exposure 0.6 to match the RRT+ODT).
Vec3f apply_tone_curve(Vec3f color, ToneCurve curve);

// The 8-bit sRGB code of a linear radiance: curve(exposure * radiance), then
// the sRGB transfer function, rounded; what a PNG pixel holds.
void tone_map_srgb8(Vec3f radiance, const ToneMapping& tone, uint8_t out[3]);

}  // namespace rf
