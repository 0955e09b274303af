// Denser pages (docs/paged-scenes.md): shared-vertex attribute pages and
// the page codecs (zstd; meshopt's vertex and index codecs, then zstd).
// Every codec gives back the raw page bit for bit; shared runs decode to
// the records they were made of; malformed streams are refused, never
// decoded into something else or read out of bounds.
#include <gtest/gtest.h>
#include <zstd.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "ooc/attribute_records.h"
#include "ooc/page_builder.h"
#include "ooc/page_codec.h"
#include "ooc/shared_attributes.h"
#include "rayforge/core/error.h"

namespace rf::pack {
namespace {

// Mesh-like shading records: corners drawn from a pool of vertices (so they
// are shared), a few materials, some triangles with tangents and some
// without uvs, ratios over many orders of magnitude.
std::vector<ShadingTriangle> mesh_like_records(size_t count, uint32_t seed, uint32_t materials = 5) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    struct Corner {
        uint32_t normal;
        Vec2f uv;
    };
    std::vector<Corner> pool(count / 2 + 3);
    for (Corner& c : pool)
        c = {encode_octahedral(normalize(Vec3f(unit(rng), unit(rng), unit(rng) + 1.5f))),
             Vec2f{unit(rng) * 40.0f, unit(rng) * 0.01f}};
    std::vector<ShadingTriangle> out(count);
    for (size_t t = 0; t < count; ++t) {
        ShadingTriangle& s = out[t];
        const size_t base = std::min(t / 2, pool.size() - 3);
        for (int c = 0; c < 3; ++c) {
            const Corner& corner = pool[base + size_t(rng() % 3)];
            s.normals[c] = corner.normal;
            s.uv[c] = corner.uv;
        }
        s.geometric_normal = normalize(Vec3f(unit(rng), unit(rng), unit(rng)));
        s.material = rng() % materials;
        s.flags = kHasNormals | (t % 7 ? kHasUvs : 0u);
        s.uv_area_ratio = (s.flags & kHasUvs) ? std::exp2(unit(rng) * 60.0f) : 0.0f;
        if (t % 5 == 0) {
            s.flags |= kHasTangent | (t % 10 == 0 ? kNegativeBitangent : 0u);
            s.tangent = encode_octahedral(normalize(Vec3f(unit(rng), unit(rng), unit(rng) + 2.0f)));
        }
    }
    return out;
}

void expect_decoded(const ShadingTriangle& want, const ShadingTriangle& got) {
    EXPECT_EQ(got.material, want.material);
    EXPECT_EQ(got.flags, want.flags);
    EXPECT_EQ(got.tangent, (want.flags & kHasTangent) ? want.tangent : 0u);
    for (int c = 0; c < 3; ++c) {
        EXPECT_EQ(got.normals[c], want.normals[c]);
        EXPECT_EQ(got.uv[c].x, want.uv[c].x);
        EXPECT_EQ(got.uv[c].y, want.uv[c].y);
    }
    EXPECT_LT(length(got.geometric_normal - want.geometric_normal), 0.06 * 3.14159265 / 180.0);  // the chord, in radians
    EXPECT_NEAR(got.uv_area_ratio, want.uv_area_ratio, 0.0014 * want.uv_area_ratio);
}

TEST(SharedAttributes, RunsDecodeToTheirRecords) {
    for (uint32_t seed : {1u, 2u, 3u}) {
        const std::vector<ShadingTriangle> records = mesh_like_records(700, seed);
        const std::vector<uint8_t> page = encode_shared_page(records);
        EXPECT_EQ(page.size(), shared_page_bytes(records));
        ASSERT_EQ(check_shared_page(page, uint32_t(records.size()), 5), "");
        EXPECT_NE(check_shared_page(page, uint32_t(records.size()), 4), "");  // a material past the file's
        EXPECT_NE(check_shared_page(page, uint32_t(records.size()) - 1, 5), "");
        for (uint32_t t = 0; t < records.size(); ++t) expect_decoded(records[t], decode_shared_record(page.data(), t));
        // Shared corners: well under three vertices a triangle.
        SharedPageHeader h;
        std::memcpy(&h, page.data(), sizeof(h));
        EXPECT_LT(h.vertex_count, records.size());
    }
}

TEST(SharedAttributes, UvAreaRatioKeepsAThousandthOfAMipLevel) {
    for (float ratio : {1e-30f, 1e-6f, 0.37f, 1.0f, 3.0f, 1e6f, 1e30f}) {
        const float back = decode_uv_area_ratio(encode_uv_area_ratio(ratio));
        EXPECT_NEAR(std::log2(back), std::log2(ratio), 1.0 / 512.0 + 1e-6) << ratio;
    }
    EXPECT_EQ(encode_uv_area_ratio(0.0f), 0);
    EXPECT_EQ(decode_uv_area_ratio(0), 0.0f);
    EXPECT_EQ(encode_uv_area_ratio(std::nanf("")), 0);
}

TEST(SharedAttributes, MalformedPagesAreRefused) {
    const std::vector<ShadingTriangle> records = mesh_like_records(64, 9);
    const std::vector<uint8_t> good = encode_shared_page(records);
    SharedPageHeader h;
    std::memcpy(&h, good.data(), sizeof(h));
    const SharedPageLayout l = shared_page_layout(h);
    std::vector<uint8_t> bad = good;
    const uint16_t past = h.vertex_count;
    std::memcpy(bad.data() + l.corners + 2, &past, 2);
    EXPECT_NE(check_shared_page(bad, 64, 5).find("past the page's vertices"), std::string::npos);
    bad = good;
    bad[l.triangles + 6] = uint8_t(h.material_count);  // material slot of triangle 0
    EXPECT_NE(check_shared_page(bad, 64, 5).find("material slot"), std::string::npos);
    bad = good;
    bad.pop_back();
    EXPECT_NE(check_shared_page(bad, 64, 5).find("wrong size"), std::string::npos);
    EXPECT_NE(check_shared_page(std::span<const uint8_t>(good.data(), 4), 64, 5), "");
    // A run of more materials than a page's slots can name is refused by the writer.
    const std::vector<ShadingTriangle> many = mesh_like_records(2000, 4, 1000);
    EXPECT_EQ(shared_page_bytes(many), SIZE_MAX);
    EXPECT_THROW((void)encode_shared_page(many), Error);
}

TEST(SharedAttributes, AttributeRunsFitTheirPagesAndKeepEveryTriangle) {
    const std::vector<ShadingTriangle> records = mesh_like_records(8192, 5, 400);
    for (uint32_t page_bytes : {1024u, 8192u, 65536u}) {
        const AttributePages cut = cut_attribute_pages(records, AttributeFormat::Shared, page_bytes);
        ASSERT_GE(cut.triangles_per_page, 1u);
        ASSERT_EQ(cut.pages.size(), (records.size() + cut.triangles_per_page - 1) / cut.triangles_per_page);
        for (const std::vector<uint8_t>& page : cut.pages) EXPECT_LE(page.size(), page_bytes);
        for (uint32_t t = 0; t < records.size(); t += 37) {
            const std::vector<uint8_t>& page = cut.pages[t / cut.triangles_per_page];
            ASSERT_EQ(check_shared_page(page, uint32_t(std::min<size_t>(cut.triangles_per_page,
                                                                          records.size() - t / cut.triangles_per_page *
                                                                                               cut.triangles_per_page)),
                                        400),
                      "");
            expect_decoded(records[t], decode_shared_record(page.data(), t % cut.triangles_per_page));
        }
    }
    // Fixed-size records: as many as fill the page.
    const AttributePages full = cut_attribute_pages(records, AttributeFormat::Full, 4096);
    EXPECT_EQ(full.triangles_per_page, 64u);
    EXPECT_EQ(full.pages.size(), 128u);
}

// A geometry page as build_page writes it: a small grid mesh cut into quads.
std::vector<uint8_t> grid_geometry_page(uint32_t side) {
    std::vector<Vec3f> positions;
    for (uint32_t y = 0; y <= side; ++y)
        for (uint32_t x = 0; x <= side; ++x)
            positions.push_back(Vec3f(float(x), std::sin(float(x + y) * 0.3f), float(y)));
    std::vector<QuadRef> quads;
    std::vector<ShadingTriangle> shading(2 * side * side);
    for (uint32_t y = 0; y < side; ++y)
        for (uint32_t x = 0; x < side; ++x) {
            QuadRef q;
            const uint32_t v = y * (side + 1) + x;
            q.v[0] = v, q.v[1] = v + 1, q.v[2] = v + side + 2, q.v[3] = v + side + 1;
            q.first = 2 * uint32_t(quads.size()), q.second = q.first + 1;
            for (int k = 0; k < 3; ++k) q.corner_of[0][k] = q.corner_of[1][k] = uint8_t(k);
            quads.push_back(q);
        }
    std::vector<uint32_t> page_quads(quads.size());
    for (uint32_t i = 0; i < page_quads.size(); ++i) page_quads[i] = i;
    const std::vector<std::vector<uint32_t>> pages = {page_quads};
    return build_page(positions, shading, quads, page_quads, lattice_steps(positions, quads, pages)).geometry;
}

struct CodecCase {
    PageKind kind;
    AttributeFormat format;
    std::vector<uint8_t> raw;
};

std::vector<CodecCase> codec_cases() {
    std::vector<CodecCase> cases;
    cases.push_back({PageKind::Geometry, AttributeFormat::Shared, grid_geometry_page(40)});
    const std::vector<ShadingTriangle> records = mesh_like_records(300, 8);
    cases.push_back({PageKind::Attributes, AttributeFormat::Shared, encode_shared_page(records)});
    for (AttributeFormat f : {AttributeFormat::Full, AttributeFormat::Compact}) {
        std::vector<uint8_t> page(records.size() * attribute_record_bytes(f));
        for (size_t i = 0; i < records.size(); ++i)
            encode_attribute_record(records[i], f, page.data() + i * attribute_record_bytes(f));
        cases.push_back({PageKind::Attributes, f, page});
    }
    std::vector<uint8_t> tile(32 * 32 * 4);
    for (size_t i = 0; i < tile.size(); ++i) tile[i] = uint8_t((i / 4) % 32 * 8 + i % 4);
    cases.push_back({PageKind::TextureTile, AttributeFormat::Shared, tile});
    return cases;
}

TEST(PageCodec, EveryCodecGivesBackThePageBitForBit) {
    for (const CodecCase& c : codec_cases())
        for (Codec codec : {Codec::None, Codec::Zstd, Codec::Meshopt}) {
            const StoredPage stored = encode_page(c.raw, c.kind, c.format, codec, 3);
            EXPECT_EQ(stored.raw_bytes, c.raw.size());
            EXPECT_LE(stored.bytes.size(), c.raw.size());
            if (codec == Codec::None) EXPECT_EQ(stored.codec, Codec::None);
            if (codec == Codec::Meshopt && c.kind == PageKind::TextureTile) EXPECT_NE(stored.codec, Codec::Meshopt);
            std::vector<uint8_t> back(c.raw.size());
            if (stored.codec == Codec::None) {
                back = stored.bytes;
            } else {
                ASSERT_TRUE(decode_page(stored.bytes, stored.codec, c.kind, c.format, back))
                    << int(c.kind) << " " << int(c.format) << " " << int(codec);
            }
            EXPECT_EQ(back, c.raw) << int(c.kind) << " " << int(c.format) << " " << int(codec);
        }
    // On a mesh's geometry page the meshopt codec is the smaller one (on the
    // random records above it need not be: the writer keeps the smaller).
    const CodecCase grid = codec_cases().front();
    const StoredPage meshopt = encode_page(grid.raw, grid.kind, grid.format, Codec::Meshopt, 3);
    EXPECT_EQ(meshopt.codec, Codec::Meshopt);
    EXPECT_LT(meshopt.bytes.size(), encode_page(grid.raw, grid.kind, grid.format, Codec::Zstd, 3).bytes.size());
}

// Corrupted streams (random bytes changed inside the zstd frame's content,
// re-framed so the damage reaches the meshopt decoders) never decode to the
// wrong size or out of bounds: decode_page says false or gives a page of
// the right size (which the reader's page checks then judge).
TEST(PageCodec, CorruptedStreamsAreRefusedOrStayInBounds) {
    std::mt19937 rng(12);
    for (const CodecCase& c : codec_cases()) {
        if (c.kind == PageKind::TextureTile) continue;
        const StoredPage stored = encode_page(c.raw, c.kind, c.format, Codec::Meshopt, 3);
        if (stored.codec != Codec::Meshopt) continue;
        std::vector<uint8_t> stream(ZSTD_getFrameContentSize(stored.bytes.data(), stored.bytes.size()));
        ASSERT_EQ(ZSTD_decompress(stream.data(), stream.size(), stored.bytes.data(), stored.bytes.size()), stream.size());
        size_t refused = 0;
        for (int trial = 0; trial < 300; ++trial) {
            std::vector<uint8_t> bad = stream;
            const int changes = 1 + int(rng() % 4);
            for (int k = 0; k < changes; ++k) bad[rng() % bad.size()] ^= uint8_t(1u << (rng() % 8));
            if (trial % 10 == 0) bad.resize(rng() % bad.size());
            std::vector<uint8_t> frame(ZSTD_compressBound(bad.size()));
            frame.resize(ZSTD_compress(frame.data(), frame.size(), bad.data(), bad.size(), 1));
            std::vector<uint8_t> back(c.raw.size());
            refused += !decode_page(frame, Codec::Meshopt, c.kind, c.format, back);
        }
        EXPECT_GT(refused, 0u);
    }
    // Not a zstd frame, and a frame claiming far more than the page.
    std::vector<uint8_t> back(1024);
    EXPECT_FALSE(decode_page(std::vector<uint8_t>(40, 7), Codec::Meshopt, PageKind::Geometry, AttributeFormat::Shared, back));
    std::vector<uint8_t> huge(1 << 20, 0);
    std::vector<uint8_t> frame(ZSTD_compressBound(huge.size()));
    frame.resize(ZSTD_compress(frame.data(), frame.size(), huge.data(), huge.size(), 1));
    EXPECT_FALSE(decode_page(frame, Codec::Meshopt, PageKind::Geometry, AttributeFormat::Shared, back));
    EXPECT_FALSE(decode_page(frame, Codec::Meshopt, PageKind::TextureTile, AttributeFormat::Shared, back));
}

}  // namespace
}  // namespace rf::pack
