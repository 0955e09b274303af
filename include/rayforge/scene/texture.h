// Textures: 8-bit sRGB-encoded (color maps) or float linear (HDR, data maps).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace rf {

enum class TextureEncoding : uint8_t {
    Srgb8,      // 8-bit per channel, sRGB transfer function (base color, emission)
    Linear8,    // 8-bit per channel, linear (normal, metallic-roughness maps)
    LinearFloat // 32-bit float per channel, linear (HDR environment maps)
};

enum class TextureWrap : uint8_t { Repeat, ClampToEdge, MirroredRepeat };

struct Texture {
    std::string name;   // usually the source path
    int width = 0;
    int height = 0;
    int channels = 0;   // 1..4
    TextureEncoding encoding = TextureEncoding::Srgb8;
    TextureWrap wrap_s = TextureWrap::Repeat;
    TextureWrap wrap_t = TextureWrap::Repeat;
    std::vector<uint8_t> texels8;   // width*height*channels, row 0 = top of image
    std::vector<float> texels_f;    // used when encoding == LinearFloat

    [[nodiscard]] size_t memory_bytes() const {
        return texels8.size() + texels_f.size() * sizeof(float);
    }
};

}  // namespace rf
