// The massive scene generator (src/ooc/generate): deterministic from the
// seed, the triangle budget met within 5%, objects well formed and within
// max_object_triangles, terrain tiles without cracks, statue copies that
// differ in shape, not only in placement, and errors for bad options. With
// ../shared the bunny is used too; without it every statue is the blob.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "ooc/generate/massive_scene.h"
#include "rayforge/core/error.h"
#include "test_paths.h"

namespace rf::pack {
namespace {

std::vector<GeneratedObject> generate_all(const GenerateOptions& options, uint64_t* emitted = nullptr) {
    std::vector<GeneratedObject> objects;
    uint64_t n = generate_scene(options, [&](const GeneratedObject& o) { objects.push_back(o); });
    if (emitted) *emitted = n;
    return objects;
}

// FNV-1a over every byte of every object, in order.
uint64_t fingerprint(const GenerateOptions& options) {
    uint64_t h = 1469598103934665603ull;
    auto add = [&](const void* data, size_t bytes) {
        for (size_t i = 0; i < bytes; ++i) h = (h ^ static_cast<const uint8_t*>(data)[i]) * 1099511628211ull;
    };
    generate_scene(options, [&](const GeneratedObject& o) {
        add(o.positions.data(), o.positions.size() * sizeof(Vec3f));
        add(o.normals.data(), o.normals.size() * sizeof(Vec3f));
        add(o.uvs.data(), o.uvs.size() * sizeof(Vec2f));
        add(o.indices.data(), o.indices.size() * sizeof(uint32_t));
        add(o.material_ids.data(), o.material_ids.size() * sizeof(uint32_t));
    });
    return h;
}

GenerateOptions options_for(uint64_t triangles, uint64_t seed = 1, const std::string& name = "terrain-statues") {
    GenerateOptions options;
    options.name = name;
    options.triangles = triangles;
    options.seed = seed;
    return options;
}

bool inside(const Box3f& box, Vec3f p) {
    return p.x >= box.lo.x && p.y >= box.lo.y && p.z >= box.lo.z && p.x <= box.hi.x && p.y <= box.hi.y &&
           p.z <= box.hi.z;
}

void expect_well_formed(const GeneratedObject& o, const GeneratedLook& look, uint64_t max_triangles) {
    ASSERT_GT(o.triangle_count(), 0u);
    ASSERT_LE(o.triangle_count(), max_triangles);
    ASSERT_EQ(o.indices.size() % 3, 0u);
    ASSERT_EQ(o.normals.size(), o.positions.size());
    ASSERT_EQ(o.uvs.size(), o.positions.size());
    ASSERT_EQ(o.material_ids.size(), o.triangle_count());
    for (uint32_t i : o.indices) ASSERT_LT(i, o.positions.size());
    for (uint32_t m : o.material_ids) ASSERT_LT(m, look.materials.size());
    for (size_t v = 0; v < o.positions.size(); ++v) {
        ASSERT_TRUE(is_finite(o.positions[v]));
        ASSERT_TRUE(inside(look.bounds, o.positions[v]));
        ASSERT_NEAR(length(o.normals[v]), 1.0f, 1e-4f);
        ASSERT_TRUE(std::isfinite(o.uvs[v].x) && std::isfinite(o.uvs[v].y));
    }
}

// Each vertex's distance from the centroid over the largest one: the same
// for two copies that differ only by scale, rotation about y and position.
std::vector<float> radial_signature(const GeneratedObject& o) {
    Vec3f centroid{0, 0, 0};
    for (Vec3f p : o.positions) centroid += p;
    centroid = centroid / float(o.positions.size());
    std::vector<float> r;
    for (Vec3f p : o.positions) r.push_back(length(p - centroid));
    float largest = *std::max_element(r.begin(), r.end());
    for (float& x : r) x /= largest;
    return r;
}

// Statue objects (material 2 and up) grouped by triangle count: same source
// and level. Expects at least one pair, and that no two are alike in shape;
// returns the triangle counts of the groups compared.
std::vector<size_t> expect_copies_differ(const std::vector<GeneratedObject>& objects) {
    std::map<size_t, std::vector<const GeneratedObject*>> by_size;
    for (const GeneratedObject& o : objects)
        if (o.material_ids[0] >= 2) by_size[o.triangle_count()].push_back(&o);
    int pairs = 0;
    std::vector<size_t> compared;
    for (const auto& [size, group] : by_size) {
        if (group.size() > 1) compared.push_back(size);
        for (size_t a = 0; a < group.size(); ++a) {
            for (size_t b = a + 1; b < group.size(); ++b, ++pairs) {
                EXPECT_EQ(group[a]->indices, group[b]->indices);  // one topology per (source, level)
                std::vector<float> ra = radial_signature(*group[a]), rb = radial_signature(*group[b]);
                float largest = 0;
                for (size_t v = 0; v < ra.size(); ++v) largest = std::max(largest, std::fabs(ra[v] - rb[v]));
                EXPECT_GT(largest, 0.01f) << size << " triangles, copies " << a << " and " << b;
            }
        }
    }
    EXPECT_GT(pairs, 0);
    return compared;
}

TEST(Generate, NamesTheScenes) {
    EXPECT_EQ(generator_names(), (std::vector<std::string>{"terrain-statues", "terrain", "forest"}));
}

TEST(Generate, IsDeterministicFromTheSeed) {
    const uint64_t first = fingerprint(options_for(200'000, 7));
    EXPECT_EQ(first, fingerprint(options_for(200'000, 7)));
    EXPECT_NE(first, fingerprint(options_for(200'000, 8)));
    EXPECT_NE(fingerprint(options_for(50'000, 7, "terrain")), fingerprint(options_for(50'000, 8, "terrain")));
}

TEST(Generate, MeetsTheTriangleBudget) {
    for (const std::string name : {"terrain-statues", "terrain"}) {
        for (uint64_t target : {1'000ull, 20'000ull, 200'000ull, 1'000'000ull}) {
            uint64_t counted = 0;
            uint64_t emitted = generate_scene(options_for(target, 3, name),
                                              [&](const GeneratedObject& o) { counted += o.triangle_count(); });
            EXPECT_EQ(emitted, counted);
            EXPECT_NEAR(double(emitted), double(target), 0.05 * double(target)) << name << " " << target;
        }
    }
}

// Triangles wound counter-clockwise seen from the side their vertex normals
// face, so shading and geometric normals agree (a few folds of a scanned
// statue aside); terrain faces up.
TEST(Generate, NormalsAgreeWithTheWinding) {
    GenerateOptions options = options_for(300'000, 6);
    options.statue_dir = test::shared_path("scenes");
    for (const GeneratedObject& o : generate_all(options)) {
        size_t agree = 0;
        for (size_t t = 0; t < o.indices.size(); t += 3) {
            Vec3f a = o.positions[o.indices[t]], b = o.positions[o.indices[t + 1]], c = o.positions[o.indices[t + 2]];
            Vec3f shading = o.normals[o.indices[t]] + o.normals[o.indices[t + 1]] + o.normals[o.indices[t + 2]];
            agree += dot(cross(b - a, c - a), shading) > 0 ? 1 : 0;
        }
        EXPECT_GT(double(agree), 0.98 * double(o.triangle_count()));
        if (o.material_ids[0] < 2) {
            for (Vec3f n : o.normals) ASSERT_GT(n.y, 0.0f);
        }
    }
}

TEST(Generate, ObjectsAreWellFormedAndWithinTheLimit) {
    GenerateOptions options = options_for(300'000, 5);
    options.max_object_triangles = 5'000;
    const GeneratedLook look = generated_look(options);
    uint64_t emitted = 0;
    const std::vector<GeneratedObject> objects = generate_all(options, &emitted);
    EXPECT_GT(objects.size(), 60u);
    for (const GeneratedObject& o : objects) expect_well_formed(o, look, options.max_object_triangles);
    EXPECT_NEAR(double(emitted), 300'000.0, 15'000.0);
}

TEST(Generate, StatueCopiesDifferInShape) {
    expect_copies_differ(generate_all(options_for(200'000, 1)));
}

// The bunny from ../shared (linked alone, so the dragon's load is skipped);
// the blob only when ../shared is missing. Parts of a split copy obey the limit.
TEST(Generate, UsesTheSharedBunnyWhenPresent) {
    const std::string bunny = test::shared_path("scenes/stanford-bunny");
    GenerateOptions options = options_for(400'000, 1);
    if (!bunny.empty()) {
        options.statue_dir = test::temp_dir("generate_bunny");
        std::filesystem::create_directory_symlink(bunny, options.statue_dir + "/stanford-bunny");
    }
    const GeneratedLook look = generated_look(options);
    const std::vector<GeneratedObject> whole = generate_all(options);
    for (const GeneratedObject& o : whole) expect_well_formed(o, look, options.max_object_triangles);
    if (!bunny.empty()) {
        EXPECT_NE(fingerprint(options), fingerprint(options_for(400'000, 1)));
    }
    const std::vector<size_t> compared = expect_copies_differ(whole);
    if (!bunny.empty()) {  // two bunnies at level 0 with this seed
        EXPECT_TRUE(std::any_of(compared.begin(), compared.end(), [](size_t n) { return n % 69451 == 0; }));
    }
    options.max_object_triangles = 20'000;
    for (const GeneratedObject& o : generate_all(options)) expect_well_formed(o, look, options.max_object_triangles);
}

// Vertices on the seam between two terrain tiles are the same in both.
TEST(Generate, TerrainTilesMeetWithoutCracks) {
    GenerateOptions options = options_for(100'000, 4, "terrain");
    options.max_object_triangles = 5'000;  // tiles of 50 x 50 cells
    const std::vector<GeneratedObject> tiles = generate_all(options);
    ASSERT_GT(tiles.size(), 4u);
    auto column = [](const GeneratedObject& o, bool right) {
        float x = right ? -1e30f : 1e30f;
        for (Vec3f p : o.positions) x = right ? std::max(x, p.x) : std::min(x, p.x);
        std::vector<std::array<float, 3>> seam;
        for (Vec3f p : o.positions)
            if (p.x == x) seam.push_back({p.x, p.y, p.z});
        std::sort(seam.begin(), seam.end());
        return seam;
    };
    std::vector<std::array<float, 3>> left_tile = column(tiles[0], true), right_tile = column(tiles[1], false);
    EXPECT_EQ(left_tile.size(), 51u);
    EXPECT_EQ(left_tile, right_tile);
}

TEST(Generate, ReportsProgressFromZeroToOne) {
    std::vector<double> fractions;
    generate_scene(options_for(100'000), [](const GeneratedObject&) {}, [&](double f) { fractions.push_back(f); });
    ASSERT_GE(fractions.size(), 3u);
    EXPECT_EQ(fractions.front(), 0.0);
    EXPECT_EQ(fractions.back(), 1.0);
    EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
}

TEST(Generate, DescribesMaterialsCameraAndLight) {
    const GeneratedLook look = generated_look(options_for(1'000'000));
    ASSERT_GE(look.materials.size(), 3u);
    for (const Material& m : look.materials) EXPECT_LT(m.base_color_texture, int32_t(look.textures.size()));
    for (const Texture& t : look.textures) {
        EXPECT_EQ(t.channels, 4);
        EXPECT_EQ(t.encoding, TextureEncoding::Srgb8);
        EXPECT_EQ(t.texels8.size(), size_t(t.width) * t.height * 4);
    }
    ASSERT_EQ(look.lights.size(), 1u);
    EXPECT_EQ(look.lights[0].type, LightType::Directional);
    EXPECT_GT(length(look.camera.target - look.camera.eye), 1.0f);
    EXPECT_TRUE(inside(look.bounds, look.camera.target));
}

TEST(Generate, RefusesBadOptions) {
    const auto sink = [](const GeneratedObject&) {};
    GenerateOptions unknown = options_for(10'000, 1, "cathedral");
    EXPECT_THROW(generate_scene(unknown, sink), Error);
    EXPECT_THROW(generated_look(unknown), Error);
    EXPECT_THROW(generate_scene(options_for(999), sink), Error);
    EXPECT_THROW(generate_scene(options_for(16'000'000'001ull), sink), Error);
    GenerateOptions tiny_objects = options_for(10'000);
    tiny_objects.max_object_triangles = 999;
    EXPECT_THROW(generate_scene(tiny_objects, sink), Error);
    GenerateOptions missing_statues = options_for(10'000);
    missing_statues.statue_dir = "/nonexistent/statues";
    EXPECT_GT(generate_scene(missing_statues, sink), 9'500u);  // the blob instead
}

}  // namespace
}  // namespace rf::pack
