// Reading textures and writing rendered images (with tone mapping for 8-bit output).
#pragma once

#include <cstdint>
#include <string>

#include "rayforge/math/vec.h"
#include "rayforge/render/image.h"
#include "rayforge/render/tone_mapping.h"
#include "rayforge/scene/texture.h"

namespace rf {

// PNG, JPEG, TGA, BMP, PPM/PGM, HDR (stb_image) and EXR (tinyexr), by content.
// 8-bit formats give `encoding8` (Srgb8 for color maps, Linear8 for data maps);
// HDR and EXR give LinearFloat. Throws rf::Error naming the file.
Texture load_texture(const std::string& path, TextureEncoding encoding8 = TextureEncoding::Srgb8);
// Same from memory (embedded glTF images); `name` is used in errors.
Texture load_texture_from_memory(const unsigned char* data, size_t size, const std::string& name,
                                 TextureEncoding encoding8 = TextureEncoding::Srgb8);

// Writes by extension: .png (8-bit sRGB of curve(exposure * radiance)),
// .exr (float RGB), .pfm (float RGB). The HDR formats stay linear: only the
// exposure scale is applied and the curve is ignored. Throws rf::Error.
void write_image(const std::string& path, const Image& image, const ToneMapping& tone);
// Same with the Clamp curve.
void write_image(const std::string& path, const Image& image, float exposure = 1.0f);
// Reads back .png (as linear after sRGB decoding), .exr and .pfm, for tests and tools.
Image read_image(const std::string& path);

}  // namespace rf
