// Ray-cone texture level of detail (Akenine-Moller et al. 2019, Ray Tracing
// Gems ch. 20) and material evaluation through mip views: levels chosen from
// hit distance and footprint, normal map decoding.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "math/color.h"
#include "render/material_eval.h"
#include "render/texture_lod.h"
#include "render/texture_mip.h"
#include "render/texture_sampling.h"

namespace rf {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(TextureLod, RayConeWidensBySpreadTimesDistance) {
    RayCone cone{0.1f, 0.01f};
    RayCone far = cone.propagate(10.0f);
    EXPECT_FLOAT_EQ(far.width, 0.2f);
    EXPECT_FLOAT_EQ(far.spread, 0.01f);
    EXPECT_FLOAT_EQ(RayCone{}.propagate(5.0f).width, 0.0f);
}

TEST(TextureLod, PixelSpreadAngleIsTheAngleOfOnePixel) {
    // 90 degrees over 2 pixels: each pixel spans tan = 1 at the centre.
    EXPECT_NEAR(pixel_spread_angle(float(kPi / 2), 2), float(kPi / 4), 1e-6f);
    double expected = std::atan(2.0 * std::tan(kPi / 6) / 720.0);
    EXPECT_NEAR(pixel_spread_angle(float(kPi / 3), 720), float(expected), 1e-9f);
}

TEST(TextureLod, UvDensityOfAScaledTriangleIsLog2OfTheScale) {
    // A triangle in a tilted plane, with uv = its in-plane coordinates * scale.
    Vec3f origin{1.0f, -2.0f, 3.0f};
    Vec3f e1 = normalize(Vec3f{1.0f, 1.0f, 0.0f});
    Vec3f e2 = normalize(cross(Vec3f{0.3f, -0.2f, 1.0f}, e1));
    e2 = normalize(e2 - e1 * dot(e2, e1));
    const Vec2f plane[3] = {{0.0f, 0.0f}, {2.0f, 0.5f}, {0.7f, 1.9f}};
    Vec3f p[3];
    for (int i = 0; i < 3; ++i) p[i] = origin + e1 * plane[i].x + e2 * plane[i].y;
    for (float scale : {1.0f, 0.25f, 3.0f, 1024.0f}) {
        Vec2f t[3];
        for (int i = 0; i < 3; ++i) t[i] = plane[i] * scale;
        EXPECT_NEAR(uv_density_log2(p[0], p[1], p[2], t[0], t[1], t[2]), std::log2(scale), 1e-5f) << scale;
    }
    // No uv area (constant uv) or no world area: the finest level.
    Vec2f same{0.3f, 0.3f};
    float flat_uv = uv_density_log2(p[0], p[1], p[2], same, same, same);
    EXPECT_TRUE(std::isinf(flat_uv) && flat_uv < 0);
    float flat_world = uv_density_log2(p[0], p[0], p[0], plane[0], plane[1], plane[2]);
    EXPECT_TRUE(std::isinf(flat_world) && flat_world < 0);
}

// A level-of-detail-only view of a width x height texture (texture_level
// reads only the base size).
MipTextureView sized_view(int width, int height) {
    MipTextureView view;
    view.levels[0].width = width;
    view.levels[0].height = height;
    view.level_count = 1;
    return view;
}

TEST(TextureLod, PrimaryConeGivesOneTexelPerPixelAtMatchingDensity) {
    // A camera with a 60 degree vertical fov and 512 rows looks at a plane
    // facing it at distance d. The texture (256x256) is stretched over a
    // square of 256 pixel footprints, i.e. one texel per pixel at distance d:
    // the level there is 0, and 1 at twice the distance (two texels per pixel).
    const float vfov = float(kPi / 3);
    const int rows = 512;
    const float d = 10.0f;
    const float pixel_size = 2.0f * d * std::tan(0.5f * vfov) / float(rows);
    const float side = 256.0f * pixel_size;
    float density = uv_density_log2({0, 0, d}, {side, 0, d}, {0, side, d}, {0, 0}, {1, 0}, {0, 1});
    MipTextureView texture = sized_view(256, 256);
    RayCone primary{0.0f, pixel_spread_angle(vfov, rows)};
    // The cone's angle is atan(x) where the pixel subtends x = tan: a tiny,
    // known offset from exactly 0.
    double x = 2.0 * std::tan(0.5 * double(vfov)) / rows;
    double offset = std::log2(std::atan(x) / x);
    for (int doubling = 0; doubling < 3; ++doubling) {
        float distance = d * float(1 << doubling);
        float facing_density = density;  // the same plane moved back keeps its uv density
        float lod = texture_level(texture, texture_lod_base(facing_density, primary.propagate(distance).width, 1.0f));
        EXPECT_NEAR(lod, double(doubling) + offset, 1e-4) << distance;
    }
    // At 60 degrees incidence the footprint is twice as long: one level coarser.
    float oblique = texture_level(texture, texture_lod_base(density, primary.propagate(d).width, 0.5f));
    EXPECT_NEAR(oblique, 1.0 + offset, 1e-4);
    // A 4x larger texture on the same triangle is two levels finer per pixel -> +2.
    EXPECT_NEAR(texture_level(sized_view(1024, 1024), texture_lod_base(density, primary.propagate(d).width, 1.0f)),
                2.0 + offset, 1e-4);
    // Grazing angles are clamped; a zero-width cone reads the finest level.
    EXPECT_TRUE(std::isfinite(texture_lod_base(density, 1.0f, 0.0f)));
    EXPECT_LT(texture_lod_base(density, 0.0f, 1.0f), -1e30f);
}

// Scene views as evaluate_material sees them: one returning mip views, one
// plain views (the older interface).
struct MipTestView {
    std::vector<MipTextureView> textures;
    const MipTextureView* texture(int32_t id) const {
        return (id >= 0 && size_t(id) < textures.size()) ? &textures[size_t(id)] : nullptr;
    }
};
struct PlainTestView {
    std::vector<TextureView> textures;
    const TextureView* texture(int32_t id) const {
        return (id >= 0 && size_t(id) < textures.size()) ? &textures[size_t(id)] : nullptr;
    }
};

Texture solid_texture(std::vector<uint8_t> texel, TextureEncoding encoding) {
    Texture t;
    t.width = t.height = 1;
    t.channels = int(texel.size());
    t.encoding = encoding;
    t.texels8 = texel;
    return t;
}

TEST(TextureLod, NormalMapDecodingAndScale) {
    Texture map = solid_texture({191, 64, 255}, TextureEncoding::Linear8);
    Texture flat_map;
    flat_map.width = flat_map.height = 1;
    flat_map.channels = 3;
    flat_map.encoding = TextureEncoding::LinearFloat;
    flat_map.texels_f = {0.5f, 0.5f, 0.5f};  // decodes to the zero vector
    MipTestView view;
    view.textures = {make_mip_view(map, nullptr), make_mip_view(flat_map, nullptr)};
    ShadingMaterial m;
    Vec3f none = sample_normal_map(view, m, Vec2f{0.5f, 0.5f}, 0.0f);
    EXPECT_EQ(none, Vec3f(0.0f, 0.0f, 1.0f));

    m.normal_texture = 0;
    float nx = 2.0f * 191.0f / 255.0f - 1.0f, ny = 2.0f * 64.0f / 255.0f - 1.0f;
    for (float scale : {1.0f, 0.5f, 2.0f, 0.0f}) {
        m.normal_scale = scale;
        Vec3f n = sample_normal_map(view, m, Vec2f{0.5f, 0.5f}, -kInfinity);
        Vec3f expected = normalize(Vec3f{nx * scale, ny * scale, 1.0f});
        EXPECT_NEAR(n.x, expected.x, 1e-6f) << scale;
        EXPECT_NEAR(n.y, expected.y, 1e-6f) << scale;
        EXPECT_NEAR(n.z, expected.z, 1e-6f) << scale;
    }
    m.normal_texture = 1;
    EXPECT_EQ(sample_normal_map(view, m, Vec2f{0.5f, 0.5f}, 0.0f), Vec3f(0.0f, 0.0f, 1.0f));

    // ShadingMaterial carries the normal map over from Material.
    Material source;
    source.normal_texture = 3;
    source.normal_scale = 0.25f;
    ShadingMaterial shading = ShadingMaterial::from(source);
    EXPECT_EQ(shading.normal_texture, 3);
    EXPECT_EQ(shading.normal_scale, 0.25f);
}

// An 8x8 sRGB checkerboard of black and white texels.
Texture checkerboard8() {
    Texture t;
    t.width = t.height = 8;
    t.channels = 3;
    t.encoding = TextureEncoding::Srgb8;
    for (int y = 0; y < 8; ++y)
        for (int x = 0; x < 8; ++x) {
            uint8_t v = ((x + y) & 1) ? 255 : 0;
            t.texels8.insert(t.texels8.end(), {v, v, v});
        }
    return t;
}

TEST(TextureLod, EvaluateMaterialFiltersByLevelOfDetail) {
    Texture board = checkerboard8();
    MipChain chain(board);
    MipTestView view;
    view.textures = {make_mip_view(board, &chain)};
    ShadingMaterial m;
    m.base_color = Vec3f(1.0f);
    m.base_color_texture = 0;
    Vec2f black_centre{0.5f / 8.0f, 0.5f / 8.0f};
    // Default (finest) and lod_base = -inf read the texel itself.
    EXPECT_EQ(evaluate_material(view, m, black_centre).base_color.x, 0.0f);
    EXPECT_EQ(evaluate_material(view, m, black_centre, -INFINITY).base_color.x, 0.0f);
    // lod_base = -3 is level 0 of an 8x8 texture; -2 is level 1, already uniform grey;
    // anything coarser stays on the 1x1 level.
    float grey = srgb_to_linear(188.0f / 255.0f);
    EXPECT_EQ(evaluate_material(view, m, black_centre, -3.0f).base_color.x, 0.0f);
    EXPECT_NEAR(evaluate_material(view, m, black_centre, -2.0f).base_color.x, grey, 1e-6f);
    EXPECT_NEAR(evaluate_material(view, m, black_centre, 5.0f).base_color.x, grey, 1e-6f);
    // Half way between level 0 and 1: half of each.
    EXPECT_NEAR(evaluate_material(view, m, black_centre, -2.5f).base_color.x, 0.5f * grey, 1e-6f);

    // A view of plain (un-mipped) textures ignores the level of detail.
    PlainTestView plain;
    plain.textures = {make_texture_view(board)};
    EXPECT_EQ(evaluate_material(plain, m, black_centre, 5.0f).base_color.x, 0.0f);
    EXPECT_EQ(evaluate_material(plain, m, black_centre).base_color.x, 0.0f);
}

}  // namespace
}  // namespace rf
