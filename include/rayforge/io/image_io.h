// Reading textures and writing rendered images (with tone mapping for 8-bit output).
#pragma once

#include <cstdint>
#include <string>

#include "rayforge/math/vec.h"
#include "rayforge/render/image.h"
#include "rayforge/scene/texture.h"

namespace rf {

// PNG, JPEG, TGA, BMP, PPM/PGM, HDR (stb_image) and EXR (tinyexr), by content.
// 8-bit formats give `encoding8` (Srgb8 for color maps, Linear8 for data maps);
// HDR and EXR give LinearFloat. Throws rf::Error naming the file.
Texture load_texture(const std::string& path, TextureEncoding encoding8 = TextureEncoding::Srgb8);
// Same from memory (embedded glTF images); `name` is used in errors.
Texture load_texture_from_memory(const unsigned char* data, size_t size, const std::string& name,
                                 TextureEncoding encoding8 = TextureEncoding::Srgb8);

// How scene-referred radiance becomes display values in [0, 1] for 8-bit output.
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

// Writes by extension: .png (8-bit sRGB of curve(exposure * radiance)),
// .exr (float RGB), .pfm (float RGB). The HDR formats stay linear: only the
// exposure scale is applied and the curve is ignored. Throws rf::Error.
void write_image(const std::string& path, const Image& image, const ToneMapping& tone);
// Same with the Clamp curve.
void write_image(const std::string& path, const Image& image, float exposure = 1.0f);
// Reads back .png (as linear after sRGB decoding), .exr and .pfm, for tests and tools.
Image read_image(const std::string& path);

}  // namespace rf
