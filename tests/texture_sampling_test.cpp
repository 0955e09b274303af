// Bilinear texture lookups, wrap modes, channel expansion and sRGB decoding.
#include <gtest/gtest.h>

#include "render/color.h"
#include "render/texture_sampling.h"

namespace rf {
namespace {

// A 2x1 grey texture: texel 0 black, texel 1 white.
Texture black_white(TextureWrap wrap, TextureEncoding encoding = TextureEncoding::Linear8) {
    Texture t;
    t.width = 2;
    t.height = 1;
    t.channels = 1;
    t.encoding = encoding;
    t.wrap_s = t.wrap_t = wrap;
    t.texels8 = {0, 255};
    return t;
}

float red_at(const Texture& t, float u, float v = 0.5f) {
    TextureView view = make_texture_view(t);
    return sample_texture(view, Vec2f{u, v}).x;
}

TEST(TextureSampling, WrapTexelFollowsEachMode) {
    EXPECT_EQ(wrap_texel(-1, 4, TextureWrap::Repeat), 3);
    EXPECT_EQ(wrap_texel(5, 4, TextureWrap::Repeat), 1);
    EXPECT_EQ(wrap_texel(-9, 4, TextureWrap::Repeat), 3);
    EXPECT_EQ(wrap_texel(-1, 4, TextureWrap::ClampToEdge), 0);
    EXPECT_EQ(wrap_texel(7, 4, TextureWrap::ClampToEdge), 3);
    EXPECT_EQ(wrap_texel(-1, 4, TextureWrap::MirroredRepeat), 0);
    EXPECT_EQ(wrap_texel(4, 4, TextureWrap::MirroredRepeat), 3);
    EXPECT_EQ(wrap_texel(6, 4, TextureWrap::MirroredRepeat), 1);
    EXPECT_EQ(wrap_texel(8, 4, TextureWrap::MirroredRepeat), 0);
    EXPECT_EQ(wrap_texel(-5, 4, TextureWrap::MirroredRepeat), 3);
}

TEST(TextureSampling, BilinearBetweenTexelCentres) {
    Texture t = black_white(TextureWrap::ClampToEdge);
    EXPECT_FLOAT_EQ(red_at(t, 0.25f), 0.0f);   // centre of texel 0
    EXPECT_FLOAT_EQ(red_at(t, 0.75f), 1.0f);   // centre of texel 1
    EXPECT_FLOAT_EQ(red_at(t, 0.5f), 0.5f);    // half way
    EXPECT_FLOAT_EQ(red_at(t, 0.375f), 0.25f); // a quarter of the way
}

TEST(TextureSampling, WrapModesAtAndBeyondTheEdges) {
    // At u = 0 the filter straddles texel -1 and texel 0.
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::Repeat), 0.0f), 0.5f);       // texel -1 = texel 1
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::ClampToEdge), 0.0f), 0.0f);  // texel -1 = texel 0
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::MirroredRepeat), 0.0f), 0.0f);
    // u = 1.25 is the centre of texel 2.
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::Repeat), 1.25f), 0.0f);          // texel 0
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::ClampToEdge), 1.25f), 1.0f);     // texel 1
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::MirroredRepeat), 1.25f), 1.0f);  // texel 1 mirrored
    EXPECT_FLOAT_EQ(red_at(black_white(TextureWrap::Repeat), -0.75f), 0.0f);         // texel -2 = texel 0
}

TEST(TextureSampling, Srgb8IsDecodedToLinearButAlphaIsNot) {
    Texture t;
    t.width = t.height = 1;
    t.channels = 4;
    t.encoding = TextureEncoding::Srgb8;
    t.texels8 = {128, 255, 0, 128};
    Vec4f c = sample_texture(make_texture_view(t), Vec2f{0.5f, 0.5f});
    EXPECT_NEAR(c.x, 0.2158605f, 1e-5f);  // sRGB 128/255 -> linear
    EXPECT_FLOAT_EQ(c.y, 1.0f);
    EXPECT_FLOAT_EQ(c.z, 0.0f);
    EXPECT_NEAR(c.w, 128.0f / 255.0f, 1e-6f);

    t.encoding = TextureEncoding::Linear8;
    c = sample_texture(make_texture_view(t), Vec2f{0.5f, 0.5f});
    EXPECT_NEAR(c.x, 128.0f / 255.0f, 1e-6f);
}

TEST(TextureSampling, ChannelExpansionAndFloatTextures) {
    Texture grey_alpha;
    grey_alpha.width = grey_alpha.height = 1;
    grey_alpha.channels = 2;
    grey_alpha.encoding = TextureEncoding::Linear8;
    grey_alpha.texels8 = {51, 102};
    Vec4f c = sample_texture(make_texture_view(grey_alpha), Vec2f{0.3f, 0.7f});
    EXPECT_FLOAT_EQ(c.x, 0.2f);
    EXPECT_FLOAT_EQ(c.z, 0.2f);
    EXPECT_FLOAT_EQ(c.w, 0.4f);

    Texture hdr;
    hdr.width = 1;
    hdr.height = 2;  // row 0 = top = v near 0
    hdr.channels = 3;
    hdr.encoding = TextureEncoding::LinearFloat;
    hdr.wrap_t = TextureWrap::ClampToEdge;
    hdr.texels_f = {10.0f, 20.0f, 30.0f, 0.5f, 0.25f, 0.125f};
    c = sample_texture(make_texture_view(hdr), Vec2f{0.5f, 0.1f});
    EXPECT_FLOAT_EQ(c.x, 10.0f);
    EXPECT_FLOAT_EQ(c.w, 1.0f);
    c = sample_texture(make_texture_view(hdr), Vec2f{0.5f, 0.9f});
    EXPECT_FLOAT_EQ(c.z, 0.125f);
}

TEST(TextureSampling, InconsistentTextureSamplesAsWhite) {
    Texture broken = black_white(TextureWrap::Repeat);
    broken.width = 1000;  // more texels claimed than stored
    TextureView view = make_texture_view(broken);
    EXPECT_FALSE(view.valid());
    Vec4f c = sample_texture(view, Vec2f{0.5f, 0.5f});
    EXPECT_EQ(c.x, 1.0f);
    EXPECT_EQ(c.w, 1.0f);
    // Non-finite coordinates do not crash and still give a texel value.
    c = sample_texture(make_texture_view(black_white(TextureWrap::Repeat)), Vec2f{NAN, INFINITY});
    EXPECT_GE(c.x, 0.0f);
    EXPECT_LE(c.x, 1.0f);
}

TEST(Color, SrgbTransferFunctionRoundTrips) {
    EXPECT_FLOAT_EQ(srgb_to_linear(0.0f), 0.0f);
    EXPECT_FLOAT_EQ(srgb_to_linear(1.0f), 1.0f);
    EXPECT_NEAR(linear_to_srgb(0.18f), 0.46135f, 1e-4f);
    for (float v = 0.0f; v <= 1.0f; v += 0.01f) EXPECT_NEAR(srgb_to_linear(linear_to_srgb(v)), v, 1e-5f);
    EXPECT_FLOAT_EQ(linear_to_srgb(2.0f), 1.0f);  // clamped
    EXPECT_EQ(linear_to_srgb(-1.0f), 0.0f);
    EXPECT_NEAR(luminance(Vec3f(1.0f)), 1.0f, 1e-6f);
}

}  // namespace
}  // namespace rf
