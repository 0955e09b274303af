// Host side of texture sampling: the 8-bit decode tables and the views of
// textures and their mip chains.
#include "render/texture_sampling.h"

#include <array>

#include "render/texture_mip.h"

namespace rf {
namespace {

std::array<float, 256> make_decode_table(TextureEncoding encoding) {
    std::array<float, 256> table{};
    for (int code = 0; code < 256; ++code) table[size_t(code)] = decode8_formula(uint8_t(code), encoding);
    return table;
}

}  // namespace

const float* srgb8_decode_table() {
    static const std::array<float, 256> table = make_decode_table(TextureEncoding::Srgb8);
    return table.data();
}

const float* linear8_decode_table() {
    static const std::array<float, 256> table = make_decode_table(TextureEncoding::Linear8);
    return table.data();
}

TextureView make_texture_view(const Texture& texture) {
    TextureView view;
    if (texture.width <= 0 || texture.height <= 0 || texture.channels < 1 || texture.channels > 4)
        return view;
    size_t expected = size_t(texture.width) * size_t(texture.height) * size_t(texture.channels);
    bool is_float = texture.encoding == TextureEncoding::LinearFloat;
    if ((is_float ? texture.texels_f.size() : texture.texels8.size()) < expected) return view;
    view.width = texture.width;
    view.height = texture.height;
    view.channels = texture.channels;
    view.encoding = texture.encoding;
    view.wrap_s = texture.wrap_s;
    view.wrap_t = texture.wrap_t;
    if (is_float) {
        view.texels_f = texture.texels_f.data();
    } else {
        view.texels8 = texture.texels8.data();
        view.decode8 = texture.encoding == TextureEncoding::Srgb8 ? srgb8_decode_table()
                                                                  : linear8_decode_table();
    }
    return view;
}

MipTextureView make_mip_view(const Texture& base, const MipChain* chain) {
    MipTextureView view;
    view.levels[0] = make_texture_view(base);
    view.level_count = 1;
    // An invalid base samples as white; coarser levels would contradict it.
    if (!chain || !view.levels[0].valid()) return view;
    for (const Texture& level : chain->levels()) {
        if (view.level_count == kMaxMipLevels) break;
        TextureView level_view = make_texture_view(level);
        if (!level_view.valid()) break;
        level_view.wrap_s = base.wrap_s;
        level_view.wrap_t = base.wrap_t;
        view.levels[view.level_count++] = level_view;
    }
    return view;
}

}  // namespace rf
