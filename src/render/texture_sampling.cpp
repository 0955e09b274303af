#include "render/texture_sampling.h"

namespace rf {

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
    if (is_float) view.texels_f = texture.texels_f.data();
    else view.texels8 = texture.texels8.data();
    return view;
}

}  // namespace rf
