// Paged texture lookups: the four taps of a bilinear lookup are found as in
// core, mapped to (tile, texel in tile) of their level and fetched together,
// one cache lookup per distinct tile (most lookups stay inside one tile),
// then decoded and blended as fetch_texel and sample_texture do.
#include "ooc/paged_texture.h"

#include <algorithm>

#include "render/texture_lod.h"
#include "render/texture_sampling.h"

namespace rf {

namespace {

// One stored texel as linear RGBA, as fetch_texel gives it: tiles hold grey
// as (g, g, g) and a missing alpha as 255, so only the alpha of a texture
// without one needs care (fetch_texel gives exactly 1 there).
Vec4f decode_texel(const float* decode8, bool has_alpha, const pack::Texel8& c) {
    const float alpha = has_alpha ? float(c[3]) * (1.0f / 255.0f) : 1.0f;
    return {decode8[c[0]], decode8[c[1]], decode8[c[2]], alpha};
}

}  // namespace

std::vector<PagedTexture> make_paged_textures(const pack::PackFile& file, pack::TextureTileCache& cache) {
    std::vector<PagedTexture> out;
    out.reserve(file.textures().size());
    for (const pack::TextureInfo& info : file.textures()) out.push_back({&info, &cache});
    return out;
}

Vec4f sample_texture(const PagedTexture& t, int level, Vec2f uv) {
    const pack::TextureInfo& info = *t.info;
    constexpr uint32_t side = pack::kTextureTileSide;
    const uint32_t width = std::max(1u, info.width >> level), height = std::max(1u, info.height >> level);
    const uint32_t tiles_x = (width + side - 1) / side;
    const BilinearTaps taps = bilinear_taps(int(width), int(height), TextureWrap(info.wrap_s),
                                            TextureWrap(info.wrap_t), uv);
    const auto address = [&](int x, int y) {
        const uint32_t ux = uint32_t(x), uy = uint32_t(y);
        return pack::TexelAddress{info.first_tile[level] + (uy / side) * tiles_x + ux / side,
                                  (uy % side) * side + ux % side};
    };
    const pack::TexelAddress addresses[4] = {address(taps.x0, taps.y0), address(taps.x1, taps.y0),
                                             address(taps.x0, taps.y1), address(taps.x1, taps.y1)};
    pack::Texel8 texels[4];
    t.cache->fetch(addresses, texels);
    // The writer stores float textures as Linear8.
    const float* decode8 = TextureEncoding(info.encoding) == TextureEncoding::Srgb8 ? srgb8_decode_table()
                                                                                    : linear8_decode_table();
    const bool has_alpha = info.channels == 2 || info.channels == 4;
    return bilinear_blend(taps, decode_texel(decode8, has_alpha, texels[0]), decode_texel(decode8, has_alpha, texels[1]),
                          decode_texel(decode8, has_alpha, texels[2]), decode_texel(decode8, has_alpha, texels[3]));
}

Vec4f sample_texture(const PagedTexture& t, Vec2f uv, float lod) {
    if (!t.info || !t.cache) return {1.0f, 1.0f, 1.0f, 1.0f};
    const MipBlend m = mip_blend(int(t.info->level_count), lod);
    const Vec4f a = sample_texture(t, m.level, uv);
    if (m.blend <= 0.0f) return a;
    return blend_texels(a, sample_texture(t, m.level + 1, uv), m.blend);
}

Vec4f sample_texture_at(const PagedTexture& t, Vec2f uv, float lod_base) {
    if (!t.info) return {1.0f, 1.0f, 1.0f, 1.0f};
    return sample_texture(t, uv, texture_level(int(t.info->width), int(t.info->height), lod_base));
}

}  // namespace rf
