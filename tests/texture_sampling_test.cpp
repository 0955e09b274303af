// Bilinear texture lookups, wrap modes, channel expansion, sRGB decoding,
// mip chains and trilinear lookups.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "math/color.h"
#include "render/texture_mip.h"
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

// --- sRGB decode tables ---------------------------------------------------

TEST(TextureSampling, DecodeTablesEqualTheFormulaForAllCodes) {
    const float* srgb = srgb8_decode_table();
    const float* linear = linear8_decode_table();
    for (int v = 0; v < 256; ++v) {
        float value = float(v) * (1.0f / 255.0f);
        EXPECT_EQ(srgb[v], srgb_to_linear(value)) << v;
        EXPECT_EQ(linear[v], value) << v;
    }
}

TEST(TextureSampling, TableAndFormulaFetchesAgree) {
    for (TextureEncoding encoding : {TextureEncoding::Srgb8, TextureEncoding::Linear8}) {
        Texture t;
        t.width = 256;
        t.height = 1;
        t.channels = 4;
        t.encoding = encoding;
        for (int v = 0; v < 256; ++v)
            for (int c = 0; c < 4; ++c) t.texels8.push_back(uint8_t((v + 64 * c) & 255));
        TextureView with_table = make_texture_view(t);
        ASSERT_NE(with_table.decode8, nullptr);
        TextureView without_table = with_table;
        without_table.decode8 = nullptr;  // a device without an uploaded table
        for (int x = 0; x < 256; ++x) {
            Vec4f a = fetch_texel(with_table, x, 0), b = fetch_texel(without_table, x, 0);
            EXPECT_EQ(a.x, b.x);
            EXPECT_EQ(a.y, b.y);
            EXPECT_EQ(a.z, b.z);
            EXPECT_EQ(a.w, b.w);
            // Alpha stays linear whatever the encoding.
            EXPECT_EQ(a.w, float((x + 192) & 255) * (1.0f / 255.0f));
        }
    }
    Texture hdr;
    hdr.width = hdr.height = hdr.channels = 1;
    hdr.encoding = TextureEncoding::LinearFloat;
    hdr.texels_f = {2.0f};
    EXPECT_EQ(make_texture_view(hdr).decode8, nullptr);
}

// --- mip chains -----------------------------------------------------------

// Deterministic bytes (a 32-bit LCG), identical on every platform.
struct Lcg {
    uint32_t state;
    uint8_t next_byte() {
        state = state * 1664525u + 1013904223u;
        return uint8_t(state >> 24);
    }
};

Texture random_texture(int width, int height, int channels, TextureEncoding encoding, uint32_t seed) {
    Texture t;
    t.width = width;
    t.height = height;
    t.channels = channels;
    t.encoding = encoding;
    Lcg rng{seed};
    size_t count = size_t(width) * size_t(height) * size_t(channels);
    if (encoding == TextureEncoding::LinearFloat) {
        for (size_t i = 0; i < count; ++i) t.texels_f.push_back(float(rng.next_byte()) * 0.1f);
    } else {
        for (size_t i = 0; i < count; ++i) t.texels8.push_back(rng.next_byte());
    }
    return t;
}

// Per-channel mean of a texture's linear RGBA values.
Vec4f linear_mean(const Texture& t) {
    TextureView view = make_texture_view(t);
    double sum[4] = {0, 0, 0, 0};
    for (int y = 0; y < t.height; ++y) {
        for (int x = 0; x < t.width; ++x) {
            Vec4f c = fetch_texel(view, x, y);
            sum[0] += c.x;
            sum[1] += c.y;
            sum[2] += c.z;
            sum[3] += c.w;
        }
    }
    double n = double(t.width) * double(t.height);
    return {float(sum[0] / n), float(sum[1] / n), float(sum[2] / n), float(sum[3] / n)};
}

std::vector<std::pair<int, int>> level_sizes(const MipChain& chain) {
    std::vector<std::pair<int, int>> sizes;
    for (const Texture& level : chain.levels()) sizes.emplace_back(level.width, level.height);
    return sizes;
}

TEST(TextureMip, ChainSizesHalveDownToOneTexel) {
    using Sizes = std::vector<std::pair<int, int>>;
    EXPECT_TRUE(MipChain(random_texture(1, 1, 4, TextureEncoding::Srgb8, 1)).levels().empty());
    EXPECT_EQ(level_sizes(MipChain(random_texture(5, 3, 3, TextureEncoding::Srgb8, 2))),
              (Sizes{{2, 1}, {1, 1}}));
    MipChain square(random_texture(256, 256, 4, TextureEncoding::Srgb8, 3));
    Sizes expected;
    size_t bytes = 0;
    for (int side = 128; side >= 1; side /= 2) {
        expected.emplace_back(side, side);
        bytes += size_t(side) * size_t(side) * 4;
    }
    EXPECT_EQ(level_sizes(square), expected);
    EXPECT_EQ(square.memory_bytes(), bytes);
    EXPECT_EQ(level_sizes(MipChain(random_texture(1024, 512, 1, TextureEncoding::Linear8, 4))),
              (Sizes{{512, 256}, {256, 128}, {128, 64}, {64, 32}, {32, 16}, {16, 8}, {8, 4}, {4, 2},
                     {2, 1}, {1, 1}}));
    // An inconsistent base has no chain.
    Texture broken = random_texture(4, 4, 3, TextureEncoding::Srgb8, 5);
    broken.height = 400;
    EXPECT_TRUE(MipChain(broken).levels().empty());
}

TEST(TextureMip, EveryLevelKeepsTheLinearAverage) {
    // Each level is filtered from the previous level's unrounded values, so its
    // mean differs from the base's only by its own 8-bit rounding: at most half
    // the largest step between adjacent codes, in linear space.
    const float srgb_half_step = 0.5f * (srgb_to_linear(1.0f) - srgb_to_linear(254.0f / 255.0f));
    const float linear_half_step = 0.5f / 255.0f;
    for (auto [w, h] : {std::pair<int, int>{37, 23}, {64, 64}, {5, 3}}) {
        Texture base = random_texture(w, h, 4, TextureEncoding::Srgb8, uint32_t(w * 131 + h));
        MipChain chain(base);
        Vec4f expected = linear_mean(base);
        ASSERT_FALSE(chain.levels().empty());
        for (const Texture& level : chain.levels()) {
            Vec4f mean = linear_mean(level);
            EXPECT_NEAR(mean.x, expected.x, srgb_half_step + 1e-5f) << w << "x" << h << " " << level.width;
            EXPECT_NEAR(mean.y, expected.y, srgb_half_step + 1e-5f);
            EXPECT_NEAR(mean.z, expected.z, srgb_half_step + 1e-5f);
            EXPECT_NEAR(mean.w, expected.w, linear_half_step + 1e-5f);
        }
        // The bound can fail: averaging the encoded codes instead would be off by far more.
        double code_sum = 0;
        for (size_t i = 0; i < base.texels8.size(); i += 4) code_sum += base.texels8[i];
        float encoded_mean = float(code_sum / double(w * h)) / 255.0f;
        EXPECT_GT(fabsf(srgb_to_linear(encoded_mean) - expected.x), 3.0f * srgb_half_step);
    }
    Texture hdr = random_texture(9, 7, 3, TextureEncoding::LinearFloat, 77);
    MipChain hdr_chain(hdr);
    Vec4f expected = linear_mean(hdr);
    for (const Texture& level : hdr_chain.levels()) {
        EXPECT_EQ(level.encoding, TextureEncoding::LinearFloat);
        Vec4f mean = linear_mean(level);
        EXPECT_NEAR(mean.x, expected.x, 1e-4f * expected.x);
        EXPECT_NEAR(mean.z, expected.z, 1e-4f * expected.z);
    }
}

// An 8x8 RGBA checkerboard of black/white texels with alternating alpha.
Texture checkerboard(TextureEncoding encoding) {
    Texture t;
    t.width = t.height = 8;
    t.channels = 4;
    t.encoding = encoding;
    for (int y = 0; y < 8; ++y) {
        for (int x = 0; x < 8; ++x) {
            uint8_t v = ((x + y) & 1) ? 255 : 0;
            t.texels8.insert(t.texels8.end(), {v, v, v, uint8_t(255 - v)});
        }
    }
    return t;
}

TEST(TextureMip, CheckerboardLevelsAreLinearMidGrey) {
    MipChain chain(checkerboard(TextureEncoding::Srgb8));
    ASSERT_EQ(chain.levels().size(), 3u);
    // 50% linear is sRGB code 188, not the code 128 that averaging encoded values gives.
    uint8_t grey = uint8_t(lrintf(linear_to_srgb(0.5f) * 255.0f));
    EXPECT_EQ(grey, 188);
    for (const Texture& level : chain.levels()) {
        for (size_t i = 0; i < level.texels8.size(); i += 4) {
            EXPECT_EQ(level.texels8[i], grey);
            EXPECT_EQ(level.texels8[i + 2], grey);
            EXPECT_EQ(level.texels8[i + 3], 128);  // alpha: 127.5 rounded
        }
        EXPECT_NEAR(fetch_texel(make_texture_view(level), 0, 0).x, 0.5f, 0.005f);
    }
    // Linear data is averaged as stored.
    MipChain data_chain(checkerboard(TextureEncoding::Linear8));
    for (const Texture& level : data_chain.levels()) EXPECT_EQ(level.texels8[0], 128);
}

TEST(TextureMip, SrgbRoundingMatchesTheTransferFunction) {
    // Every pair of sRGB codes side by side: level 1 holds the rounded
    // encoding of each pair's linear mean. The chain is also long enough to
    // reach the level cap.
    Texture pairs;
    pairs.width = 2 * 256 * 256;
    pairs.height = 1;
    pairs.channels = 1;
    pairs.encoding = TextureEncoding::Srgb8;
    for (int a = 0; a < 256; ++a)
        for (int b = 0; b < 256; ++b) pairs.texels8.insert(pairs.texels8.end(), {uint8_t(a), uint8_t(b)});
    MipChain chain(pairs);
    ASSERT_EQ(int(chain.levels().size()), kMaxMipLevels - 1);
    EXPECT_EQ(chain.levels().back().width, pairs.width >> (kMaxMipLevels - 1));
    const Texture& level = chain.levels()[0];
    ASSERT_EQ(level.width, 256 * 256);
    int off_by_one = 0;
    for (int a = 0; a < 256; ++a) {
        for (int b = 0; b < 256; ++b) {
            float mean = 0.5f * srgb_to_linear(float(a) / 255.0f) + 0.5f * srgb_to_linear(float(b) / 255.0f);
            float encoded = linear_to_srgb(mean) * 255.0f;
            int got = level.texels8[size_t(a * 256 + b)];
            int expected = int(lrintf(encoded));
            if (got == expected) continue;
            // Only float-vs-double disagreements right at a rounding midpoint.
            EXPECT_EQ(std::abs(got - expected), 1) << a << " " << b;
            EXPECT_LT(fabsf(encoded - (floorf(encoded) + 0.5f)), 1e-3f) << a << " " << b;
            ++off_by_one;
        }
    }
    EXPECT_LT(off_by_one, 64);
}

// --- trilinear lookups ----------------------------------------------------

float max_difference(Vec4f a, Vec4f b) {
    return fmaxf(fmaxf(fabsf(a.x - b.x), fabsf(a.y - b.y)), fmaxf(fabsf(a.z - b.z), fabsf(a.w - b.w)));
}

const Vec2f kProbeUvs[] = {{0.5f, 0.5f}, {0.03f, 0.91f}, {0.77f, 0.12f}, {-0.4f, 1.3f}, {0.999f, 0.001f}};

TEST(TextureMip, MipViewListsTheChain) {
    Texture base = random_texture(16, 8, 3, TextureEncoding::Srgb8, 9);
    base.wrap_s = TextureWrap::ClampToEdge;
    MipChain chain(base);
    MipTextureView view = make_mip_view(base, &chain);
    ASSERT_EQ(view.level_count, 5);
    EXPECT_EQ(view.base().width, 16);
    EXPECT_EQ(view.levels[4].width, 1);
    EXPECT_EQ(view.levels[2].wrap_s, TextureWrap::ClampToEdge);
    EXPECT_EQ(make_mip_view(base, nullptr).level_count, 1);
}

TEST(TextureMip, TrilinearAtIntegerLodsIsBilinearOnThatLevel) {
    Texture base = random_texture(16, 16, 4, TextureEncoding::Srgb8, 11);
    MipChain chain(base);
    MipTextureView view = make_mip_view(base, &chain);
    ASSERT_EQ(view.level_count, 5);
    for (Vec2f uv : kProbeUvs) {
        for (int level = 0; level < view.level_count; ++level) {
            Vec4f expected = sample_texture(view.levels[level], uv);
            EXPECT_EQ(max_difference(sample_texture(view, uv, float(level)), expected), 0.0f) << level;
        }
        // Past the last level: the last level alone.
        Vec4f last = sample_texture(view.levels[4], uv);
        EXPECT_EQ(max_difference(sample_texture(view, uv, 4.5f), last), 0.0f);
        EXPECT_EQ(max_difference(sample_texture(view, uv, 40.0f), last), 0.0f);
        EXPECT_EQ(max_difference(sample_texture(view, uv, INFINITY), last), 0.0f);
        // Half way between levels: the mean of the two.
        Vec4f a = sample_texture(view.levels[1], uv), b = sample_texture(view.levels[2], uv);
        Vec4f mid = sample_texture(view, uv, 1.5f);
        EXPECT_NEAR(mid.x, 0.5f * (a.x + b.x), 1e-6f);
        EXPECT_NEAR(mid.w, 0.5f * (a.w + b.w), 1e-6f);
    }
}

TEST(TextureMip, TrilinearIsContinuousAcrossLod) {
    Texture base = random_texture(32, 16, 3, TextureEncoding::Srgb8, 13);
    MipChain chain(base);
    MipTextureView view = make_mip_view(base, &chain);
    // The value moves by at most (difference between adjacent levels) * dlod,
    // and linear values lie in [0, 1], so a step of eps moves it by <= eps.
    const float eps = 1e-3f;
    for (Vec2f uv : kProbeUvs) {
        for (int level = 0; level < view.level_count; ++level) {
            Vec4f at = sample_texture(view, uv, float(level));
            EXPECT_LE(max_difference(sample_texture(view, uv, float(level) - eps), at), eps + 1e-6f);
            EXPECT_LE(max_difference(sample_texture(view, uv, float(level) + eps), at), eps + 1e-6f);
        }
        for (float lod = 0.0f; lod < 6.0f; lod += 0.05f) {
            Vec4f here = sample_texture(view, uv, lod), next = sample_texture(view, uv, lod + 0.05f);
            EXPECT_LE(max_difference(here, next), 0.05f + 1e-6f) << lod;
        }
    }
}

TEST(TextureMip, NonPositiveLodIsTheOldBilinear) {
    Texture base = random_texture(8, 8, 2, TextureEncoding::Linear8, 17);
    MipChain chain(base);
    MipTextureView view = make_mip_view(base, &chain);
    MipTextureView single = make_mip_view(base, nullptr);
    TextureView plain = make_texture_view(base);
    for (Vec2f uv : kProbeUvs) {
        Vec4f expected = sample_texture(plain, uv);
        for (float lod : {0.0f, -0.5f, -3.0f, -3.402823466e+38f, -INFINITY, NAN}) {
            EXPECT_EQ(max_difference(sample_texture(view, uv, lod), expected), 0.0f) << lod;
        }
        // Without a chain every lod reads level 0.
        EXPECT_EQ(max_difference(sample_texture(single, uv, 2.5f), expected), 0.0f);
    }
    // An invalid base samples as white at any level.
    Texture broken = base;
    broken.width = 100;
    MipChain broken_chain(broken);
    Vec4f white = sample_texture(make_mip_view(broken, &broken_chain), Vec2f{0.5f, 0.5f}, 2.0f);
    EXPECT_EQ(white.x, 1.0f);
    EXPECT_EQ(white.w, 1.0f);
}

}  // namespace
}  // namespace rf
