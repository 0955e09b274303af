// Paged textures (ooc/texture_cache.h, ooc/paged_texture.h) on a small pack
// file written by PackWriter: lookups through the tile cache equal the
// in-core lookups of the same textures (make_mip_view over MipChain) for
// random uv and levels of detail, with every encoding, channel count and wrap
// mode, stored raw or zstd-compressed; a 16-tile cache serving many threads
// stays within its budget and agrees with a roomy one; the statistics; the
// clock keeps a tile in steady use; a corrupted tile is an error naming its
// page and the cache goes on serving the others.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/parallel.h"
#include "ooc/pack_file.h"
#include "ooc/pack_writer.h"
#include "ooc/paged_texture.h"
#include "ooc/texture_cache.h"
#include "rayforge/core/error.h"
#include "render/material_eval.h"
#include "render/texture_mip.h"
#include "render/texture_sampling.h"
#include "test_paths.h"

namespace rf {
namespace {

using pack::TextureTileCache;

Texture random_texture(int width, int height, int channels, TextureEncoding encoding, TextureWrap wrap_s,
                       TextureWrap wrap_t, uint32_t seed) {
    Texture t;
    t.name = std::to_string(width) + "x" + std::to_string(height);
    t.width = width;
    t.height = height;
    t.channels = channels;
    t.encoding = encoding;
    t.wrap_s = wrap_s;
    t.wrap_t = wrap_t;
    std::mt19937 rng(seed);
    const size_t values = size_t(width) * size_t(height) * size_t(channels);
    if (encoding == TextureEncoding::LinearFloat) {
        t.texels_f.resize(values);
        for (float& v : t.texels_f) v = std::uniform_real_distribution<float>(0.0f, 1.0f)(rng);
    } else {
        t.texels8.resize(values);
        for (uint8_t& v : t.texels8) v = uint8_t(rng());
    }
    return t;
}

// Odd sizes, every channel count, encoding and wrap mode.
std::vector<Texture> test_textures() {
    using E = TextureEncoding;
    using W = TextureWrap;
    return {
        random_texture(1, 1, 3, E::Srgb8, W::Repeat, W::Repeat, 1),
        random_texture(37, 19, 1, E::Linear8, W::Repeat, W::Repeat, 2),
        random_texture(100, 64, 3, E::Srgb8, W::ClampToEdge, W::MirroredRepeat, 3),
        random_texture(256, 256, 4, E::Srgb8, W::Repeat, W::Repeat, 4),
        random_texture(23, 41, 2, E::Srgb8, W::MirroredRepeat, W::ClampToEdge, 5),
        random_texture(45, 30, 4, E::LinearFloat, W::Repeat, W::MirroredRepeat, 6),
    };
}
constexpr size_t kBigTexture = 3;    // 256x256 RGBA
constexpr size_t kFloatTexture = 5;  // stored as linear 8-bit

// A pack file of `textures` (and one material), nothing else.
std::string write_texture_pack(const std::string& name, const std::vector<Texture>& textures,
                               pack::Codec codec = pack::Codec::None) {
    const std::string path = test::temp_dir("paged_texture_" + name) + "/textures.rfpack";
    pack::PackWriterOptions options;
    options.codec = codec;
    pack::PackWriter writer(path, options);
    writer.add_material(ShadingMaterial::from(Material{}));
    for (const Texture& t : textures) writer.add_texture(t);
    writer.finish();  // no geometry: a file of texture pages only is valid
    return path;
}

// In-core views of the same textures.
struct InCore {
    explicit InCore(const std::vector<Texture>& textures) : textures(textures) {
        chains.reserve(textures.size());
        for (const Texture& t : this->textures) chains.emplace_back(t);
        for (size_t i = 0; i < textures.size(); ++i) views.push_back(make_mip_view(this->textures[i], &chains[i]));
    }
    std::vector<Texture> textures;
    std::vector<MipChain> chains;
    std::vector<MipTextureView> views;
};

struct Lookup {
    uint32_t texture = 0;
    Vec2f uv;
    float lod_base = 0.0f;
};

// Random lookups: uv around and beyond [0, 1], levels of detail over every
// mip level and past them, now and then infinite or NaN.
std::vector<Lookup> random_lookups(size_t count, uint32_t textures, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uv(-2.0f, 3.0f), lod(-11.0f, 3.0f);
    std::vector<Lookup> out(count);
    for (Lookup& l : out) {
        l.texture = rng() % textures;
        l.uv = {uv(rng), uv(rng)};
        l.lod_base = lod(rng);
        switch (rng() % 16) {
            case 0: l.lod_base = -std::numeric_limits<float>::infinity(); break;
            case 1: l.lod_base = std::numeric_limits<float>::infinity(); break;
            case 2: l.lod_base = std::numeric_limits<float>::quiet_NaN(); break;
            case 3: l.lod_base = std::round(l.lod_base); break;  // exactly on a level
            default: break;
        }
    }
    return out;
}

// 8-bit storage of a float texture: each texel within half a code, so each
// filtered value (a convex combination) too, plus float rounding.
constexpr float kFloatTolerance = 0.5f / 255.0f + 1e-6f;

void expect_same(Vec4f paged, Vec4f in_core, bool float_texture, const Lookup& l) {
    const float got[4] = {paged.x, paged.y, paged.z, paged.w}, want[4] = {in_core.x, in_core.y, in_core.z, in_core.w};
    for (int c = 0; c < 4; ++c) {
        if (float_texture)
            ASSERT_NEAR(got[c], want[c], kFloatTolerance) << "texture " << l.texture << " channel " << c;
        else
            ASSERT_EQ(got[c], want[c]) << "texture " << l.texture << " channel " << c << " uv " << l.uv.x << ","
                                       << l.uv.y << " lod_base " << l.lod_base;
    }
}

void expect_equal_to_in_core(pack::Codec codec, const std::string& name) {
    const std::vector<Texture> textures = test_textures();
    const InCore in_core(textures);
    const pack::PackFile file(write_texture_pack(name, textures, codec));
    ASSERT_EQ(file.textures().size(), textures.size());
    TextureTileCache cache(file, size_t(64) << 20);
    ASSERT_EQ(cache.slot_count(), file.header().texture_pages);  // roomy: every tile fits
    const std::vector<PagedTexture> paged = make_paged_textures(file, cache);
    for (size_t i = 0; i < textures.size(); ++i)
        ASSERT_EQ(int(file.textures()[i].level_count), in_core.views[i].level_count) << "texture " << i;
    for (const Lookup& l : random_lookups(20000, uint32_t(textures.size()), 7)) {
        const Vec4f got = sample_texture_at(paged[l.texture], l.uv, l.lod_base);
        const Vec4f want = sample_texture_at(in_core.views[l.texture], l.uv, l.lod_base);
        expect_same(got, want, l.texture == kFloatTexture, l);
    }
}

TEST(PagedTexture, EqualsTheInCoreLookup) { expect_equal_to_in_core(pack::Codec::None, "raw"); }

TEST(PagedTexture, EqualsTheInCoreLookupWithCompressedTiles) {
    expect_equal_to_in_core(pack::Codec::Zstd, "zstd");
}

// Through the material templates, which find the overload by argument-dependent lookup.
struct PagedView {
    const std::vector<PagedTexture>* textures = nullptr;
    const PagedTexture* texture(int32_t id) const {
        return id >= 0 && size_t(id) < textures->size() ? &(*textures)[size_t(id)] : nullptr;
    }
};
struct InCoreView {
    const std::vector<MipTextureView>* textures = nullptr;
    const MipTextureView* texture(int32_t id) const {
        return id >= 0 && size_t(id) < textures->size() ? &(*textures)[size_t(id)] : nullptr;
    }
};

TEST(PagedTexture, MaterialEvaluationMatchesInCore) {
    const std::vector<Texture> textures = test_textures();
    const InCore in_core(textures);
    const pack::PackFile file(write_texture_pack("material", textures));
    TextureTileCache cache(file, size_t(64) << 20);
    const std::vector<PagedTexture> paged = make_paged_textures(file, cache);
    ShadingMaterial m = ShadingMaterial::from(Material{});
    m.base_color_texture = int32_t(kBigTexture);
    m.metallic_roughness_texture = 2;
    m.emission_texture = 4;
    m.emission = {1.0f, 2.0f, 3.0f};
    m.normal_texture = 1;
    for (const Lookup& l : random_lookups(2000, 1, 11)) {
        const MaterialSample a = evaluate_material(PagedView{&paged}, m, l.uv, l.lod_base);
        const MaterialSample b = evaluate_material(InCoreView{&in_core.views}, m, l.uv, l.lod_base);
        ASSERT_EQ(std::memcmp(&a, &b, sizeof(a)), 0);
        const Vec3f na = sample_normal_map(PagedView{&paged}, m, l.uv, l.lod_base);
        const Vec3f nb = sample_normal_map(InCoreView{&in_core.views}, m, l.uv, l.lod_base);
        ASSERT_EQ(std::memcmp(&na, &nb, sizeof(na)), 0);
    }
}

TEST(TextureTileCache, BudgetBoundsSlotsAndMemory) {
    const pack::PackFile file(write_texture_pack("budget", test_textures()));
    const size_t budget = TextureTileCache::budget_for_slots(TextureTileCache::kMinSlots);
    const TextureTileCache small(file, budget);
    EXPECT_EQ(small.slot_count(), TextureTileCache::kMinSlots);
    EXPECT_LE(small.memory_bytes(), budget);
    EXPECT_GE(small.memory_bytes(), size_t(TextureTileCache::kMinSlots) * TextureTileCache::kTileBytes);
    for (size_t b : {size_t(1) << 18, size_t(1) << 20, size_t(3) << 20}) {
        const TextureTileCache cache(file, b);
        EXPECT_LE(cache.memory_bytes(), b);
        EXPECT_LE(cache.slot_count(), cache.page_count());
        EXPECT_GE(cache.shard_count(), 1u);
        EXPECT_LE(cache.shard_count(), TextureTileCache::kMaxShards);
    }
    try {
        const TextureTileCache too_small(file, budget - 1, "tiny textures");
        FAIL() << "a budget below 16 tiles was accepted";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find("tiny textures"), std::string::npos) << message;
        EXPECT_NE(message.find("at least 16"), std::string::npos) << message;
        EXPECT_NE(message.find(std::to_string(budget)), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

TEST(TextureTileCache, AFileWithoutTexturesNeedsNoPool) {
    const pack::PackFile file(write_texture_pack("none", {}));
    const TextureTileCache cache(file, 0);
    EXPECT_EQ(cache.page_count(), 0u);
    EXPECT_EQ(cache.slot_count(), 0u);
    EXPECT_EQ(cache.memory_bytes(), 0u);
    EXPECT_EQ(cache.cached_count(), 0u);
}

TEST(TextureTileCache, FewTilesNeedFewSlots) {
    const pack::PackFile file(write_texture_pack("few", {test_textures()[0]}));  // 1x1: one tile
    ASSERT_EQ(file.header().texture_pages, 1u);
    const TextureTileCache cache(file, TextureTileCache::budget_for_slots(1));
    EXPECT_EQ(cache.slot_count(), 1u);
}

// Many threads through a 16-tile cache: the same values as a roomy cache,
// and never more memory than the budget.
TEST(TextureTileCache, SmallCacheUnderManyThreadsMatchesARoomyOne) {
    const std::vector<Texture> textures = test_textures();
    const pack::PackFile file(write_texture_pack("threads", textures, pack::Codec::Zstd));
    const size_t budget = TextureTileCache::budget_for_slots(16);
    TextureTileCache small(file, budget), roomy(file, size_t(64) << 20);
    ASSERT_EQ(small.slot_count(), 16u);
    const std::vector<PagedTexture> small_textures = make_paged_textures(file, small);
    const std::vector<PagedTexture> roomy_textures = make_paged_textures(file, roomy);
    const std::vector<Lookup> lookups = random_lookups(40000, uint32_t(textures.size()), 13);
    std::vector<Vec4f> expected(lookups.size()), got(lookups.size());
    for (size_t i = 0; i < lookups.size(); ++i)
        expected[i] = sample_texture_at(roomy_textures[lookups[i].texture], lookups[i].uv, lookups[i].lod_base);
    parallel::for_range(size_t(0), lookups.size(), size_t(64), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i)
            got[i] = sample_texture_at(small_textures[lookups[i].texture], lookups[i].uv, lookups[i].lod_base);
    });
    for (size_t i = 0; i < lookups.size(); ++i)
        ASSERT_EQ(std::memcmp(&got[i], &expected[i], sizeof(Vec4f)), 0) << "lookup " << i;
    EXPECT_LE(small.memory_bytes(), budget);
    EXPECT_LE(small.cached_count(), 16u);
    const pack::PageCacheStats s = small.stats();
    EXPECT_EQ(s.requests, s.hits + s.misses);
    EXPECT_EQ(s.pages_read, s.misses);
    EXPECT_EQ(s.evictions, s.pages_read - small.cached_count());
    EXPECT_GT(s.evictions, 0u);
}

TEST(TextureTileCache, StatisticsCountLookupsReadsAndEvictions) {
    const pack::PackFile file(write_texture_pack("stats", test_textures()));
    TextureTileCache cache(file, size_t(64) << 20);
    const uint64_t tile_bytes = TextureTileCache::kTileBytes;
    EXPECT_EQ(cache.fetch({0, 0})[3], 255);  // the 1x1 RGB texture: its alpha filled in
    pack::PageCacheStats s = cache.stats();
    EXPECT_EQ(s.requests, 1u);
    EXPECT_EQ(s.misses, 1u);
    EXPECT_EQ(s.hits, 0u);
    EXPECT_EQ(s.pages_read, 1u);
    EXPECT_EQ(s.bytes_read, tile_bytes);
    EXPECT_EQ(s.evictions, 0u);
    EXPECT_GE(s.io_ms, 0.0);
    // Four texels in two tiles: two lookups, one of them a hit.
    const pack::TexelAddress four[4] = {{0, 0}, {1, 5}, {0, 0}, {1, 1023}};
    pack::Texel8 out[4];
    cache.fetch(four, out);
    EXPECT_EQ(out[0], out[2]);
    s = cache.stats();
    EXPECT_EQ(s.requests, 3u);
    EXPECT_EQ(s.hits, 1u);
    EXPECT_EQ(s.misses, 2u);
    EXPECT_EQ(s.pages_read, 2u);
    EXPECT_EQ(cache.cached_count(), 2u);
    cache.clear();
    EXPECT_EQ(cache.cached_count(), 0u);
    EXPECT_EQ(cache.stats().requests, 3u);  // clear() keeps the stats
    cache.reset_stats();
    EXPECT_EQ(cache.stats().requests, 0u);
    EXPECT_THROW((void)cache.fetch({cache.page_count(), 0}), Error);
    EXPECT_THROW((void)cache.fetch({0, 1024}), Error);

    // Every tile once through 16 slots: each read after the pool filled evicts one.
    TextureTileCache small(file, TextureTileCache::budget_for_slots(16));
    for (uint32_t tile = 0; tile < small.page_count(); ++tile) (void)small.fetch({tile, 0});
    s = small.stats();
    EXPECT_EQ(s.misses, small.page_count());
    EXPECT_EQ(s.evictions, small.page_count() - small.cached_count());
    EXPECT_LE(small.cached_count(), 16u);
}

// A tile used between every other miss is never the clock's victim.
TEST(TextureTileCache, ATileInSteadyUseStays) {
    const pack::PackFile file(write_texture_pack("steady", test_textures()));
    TextureTileCache cache(file, TextureTileCache::budget_for_slots(16));
    const uint32_t hot = 7;
    for (uint32_t tile = 0; tile < cache.page_count(); ++tile) {
        (void)cache.fetch({hot, 0});
        if (tile != hot) (void)cache.fetch({tile, 0});
    }
    const pack::PageCacheStats s = cache.stats();
    EXPECT_EQ(s.misses, cache.page_count());  // each tile read once: the hot one never again
    EXPECT_GT(s.evictions, 0u);
}

TEST(TextureTileCache, ACorruptedTileIsAnErrorNamingItsPage) {
    const std::vector<Texture> textures = test_textures();
    const InCore in_core(textures);
    const std::string path = write_texture_pack("corrupt", textures);
    // Texel (101, 71) of the big texture's level 0: tile (3, 2) of its 8x8.
    uint64_t page = 0;
    {
        const pack::PackFile file(path);
        const pack::TextureInfo& big = file.textures()[kBigTexture];
        page = file.first_texture_page() + big.first_tile[0] + 2 * 8 + 3;
        std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
        const uint64_t at = file.directory()[page].offset + (7 * 32 + 5) * 4;
        f.seekg(std::streamoff(at));
        char byte = 0;
        f.read(&byte, 1);
        byte = char(byte ^ 0x5A);
        f.seekp(std::streamoff(at));
        f.write(&byte, 1);
    }
    const pack::PackFile file(path);
    TextureTileCache cache(file, TextureTileCache::budget_for_slots(16));
    const std::vector<PagedTexture> paged = make_paged_textures(file, cache);
    const Vec2f on_bad_tile{(101.0f + 0.5f) / 256.0f, (71.0f + 0.5f) / 256.0f};
    const float finest = -std::numeric_limits<float>::infinity();
    for (int attempt = 0; attempt < 2; ++attempt) {  // not cached after a failure: fails again
        try {
            (void)sample_texture_at(paged[kBigTexture], on_bad_tile, finest);
            FAIL() << "a corrupted tile was sampled";
        } catch (const Error& e) {
            const std::string message = e.what();
            EXPECT_NE(message.find("page " + std::to_string(page)), std::string::npos) << message;
            EXPECT_NE(message.find("checksum"), std::string::npos) << message;
            EXPECT_EQ(message.find('\n'), std::string::npos) << message;
        }
    }
    // Level 1 and the other textures still serve, and equal the in-core values.
    EXPECT_EQ(sample_texture(paged[kBigTexture], on_bad_tile, 1.0f).x,
              sample_texture(in_core.views[kBigTexture], on_bad_tile, 1.0f).x);
    for (const Lookup& l : random_lookups(3000, uint32_t(textures.size()), 17)) {
        if (l.texture == kBigTexture) continue;
        expect_same(sample_texture_at(paged[l.texture], l.uv, l.lod_base),
                    sample_texture_at(in_core.views[l.texture], l.uv, l.lod_base), l.texture == kFloatTexture, l);
    }
    const pack::PageCacheStats s = cache.stats();
    EXPECT_EQ(s.misses, s.pages_read + 2);  // the two failed reads
    EXPECT_LE(cache.cached_count(), 16u);
}

}  // namespace
}  // namespace rf
