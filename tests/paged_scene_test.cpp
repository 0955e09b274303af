// Paged scenes (docs/paged-scenes.md): the file round trip, the out-of-core traversal
// against brute force over the same quantised pages, paged against in-core
// hits, eviction under tiny budgets, corrupted and truncated files.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <random>

#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "ooc/convert_scene.h"
#include "ooc/pack_file.h"
#include "ooc/page_cache.h"
#include "ooc/paged_engine.h"
#include "ooc/paged_traversal.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

using namespace rf::pack;

// A scene of instanced spheres over a ground plane, paged.
struct PagedFixture {
    Scene scene;
    SceneGeometry geometry;
    std::string path;
    ConvertResult converted;
};

const PagedFixture& fixture(AttributeFormat format = AttributeFormat::Full, TopLevel top = TopLevel::WideBvh) {
    static std::map<int, std::unique_ptr<PagedFixture>> cache;
    auto& slot = cache[int(format) * 2 + int(top)];
    if (!slot) {
        slot = std::make_unique<PagedFixture>();
        slot->scene = make_builtin_scene("spheres");
        slot->scene.finalize();
        slot->geometry = SceneGeometry::build(slot->scene);
        slot->path = test::temp_dir("paged_fixture_" + std::to_string(int(format)) + "_" + std::to_string(int(top))) +
                     "/spheres.rfpack";
        PackWriterOptions options;
        options.top_level = top;
        options.attribute_format = format;
        options.quads_per_page = 512;  // many pages from a small scene
        options.codec = format == AttributeFormat::Compact  ? Codec::Zstd
                        : format == AttributeFormat::Shared ? Codec::Meshopt
                                                            : Codec::None;
        slot->converted = convert_scene(slot->scene, slot->path, options);
    }
    return *slot;
}

// Closest hit over every quad of every page, through every top reference:
// a world-space page decoded in world space, an instanced one in its
// object's space with the ray taken there (as the traversal does). The
// instance of the hit in `instance`.
Hit brute_force(const PackFile& file, const std::vector<std::vector<uint8_t>>& pages, const Ray& world,
                uint32_t* instance = nullptr) {
    Hit best;
    best.t = world.tmax;
    uint32_t best_instance = kNoInstance;
    for (const TopRef& ref : file.top_refs()) {
        const Ray ray = ref.instance == kNoInstance ? world : pack::detail::object_ray(file.instances()[ref.instance], world);
        const WatertightRay wt = WatertightRay::make(ray);
        const GeometryPageView g = view_geometry_page(pages[ref.page], "page");
        const PageInfo& info = file.pages()[ref.page];
        for (uint32_t q = 0; q < g.quad_count; ++q)
            for (int half = 0; half < 2; ++half) {
                TriangleHit th;
                if (intersect_triangle(wt, pack::detail::decoded_quad_half(g.quads[q], half, info), world.tmin, best.t,
                                       th)) {
                    best.t = th.t;
                    best.u = th.u;
                    best.v = th.v;
                    best.prim = ref.page * kTrianglesPerPageSlot + 2 * q + uint32_t(half);
                    best_instance = ref.instance;
                }
            }
    }
    if (!best.found()) best = Hit{};
    if (instance) *instance = best.found() ? best_instance : kNoInstance;
    return best;
}

std::vector<std::vector<uint8_t>> read_all_geometry(const PackFile& file) {
    std::vector<std::vector<uint8_t>> pages(file.header().geometry_pages);
    std::vector<uint8_t> scratch;
    for (uint32_t p = 0; p < pages.size(); ++p) file.read_page(p, pages[p], scratch);
    return pages;
}

TEST(PagedScene, RoundTripKeepsCountsAndBoundsQuantisation) {
    const PagedFixture& f = fixture();
    const PackFile file(f.path);
    // A mesh placed once is written once in world space, a mesh placed more
    // often once in its own space plus an instance per placement.
    std::vector<uint32_t> uses(f.scene.meshes.size(), 0);
    for (const Instance& i : f.scene.instances) ++uses[i.mesh];
    uint64_t unique = 0, placed = 0, instances = 0;
    for (size_t m = 0; m < uses.size(); ++m) {
        unique += uses[m] > 0 ? f.scene.meshes[m].triangle_count() : 0;
        if (uses[m] > 1) {
            placed += uses[m] * f.scene.meshes[m].triangle_count();
            instances += uses[m];
        }
    }
    ASSERT_GT(instances, 0u) << "the fixture has no instanced mesh";
    EXPECT_EQ(file.header().triangle_count, unique);
    EXPECT_EQ(f.converted.summary.triangles, unique);
    EXPECT_EQ(f.converted.summary.instanced_triangles, placed);
    EXPECT_EQ(file.instances().size(), instances);
    EXPECT_EQ(file.header().geometry_pages, f.converted.summary.geometry_pages);
    EXPECT_GT(file.header().geometry_pages, 10u);
    // Expanded through its instances, the file holds the scene's triangles.
    EXPECT_EQ(decode_paged_geometry(f.path).geometry.triangles.size(), f.geometry.size());
    // Most triangles find a partner on closed, indexed meshes.
    EXPECT_GT(double(f.converted.summary.paired_triangles), 0.9 * double(unique));
    // Quantisation error at most half a step of the largest page's 16-bit grid.
    double largest_step = 0.0;
    for (const PageInfo& p : file.pages()) largest_step = std::max({largest_step, double(p.scale.x), double(p.scale.y), double(p.scale.z)});
    EXPECT_LE(f.converted.summary.max_quantisation_error, 0.5 * largest_step * 1.001);
    EXPECT_GT(f.converted.summary.max_quantisation_error, 0.0);
    // Every page's bounds hold its decoded quads, and the BVH boxes hold their quads.
    const auto pages = read_all_geometry(file);
    for (uint32_t p = 0; p < pages.size(); ++p) {
        const GeometryPageView g = view_geometry_page(pages[p], "page");
        const PageInfo& info = file.pages()[p];
        for (uint32_t q = 0; q < g.quad_count; ++q)
            for (const auto& v : g.quads[q].v) {
                const Vec3f w = info.offset + info.scale * Vec3f(float(v[0]), float(v[1]), float(v[2]));
                for (int a = 0; a < 3; ++a) {
                    ASSERT_GE(w[a], info.bounds.lo[a]);
                    ASSERT_LE(w[a], info.bounds.hi[a]);
                }
            }
        // Every quad is in exactly one leaf slot, inside the slot's box.
        std::vector<int> leaf_of_quad(g.quad_count, 0);
        for (uint32_t n = 0; n < g.node_count; ++n) {
            const PageNode& node = g.nodes[n];
            for (int s = 0; s < kCwbvhWidth; ++s) {
                if (node.meta[s] == kCwbvhEmptyMeta || cwbvh_meta_is_inner(node.meta[s])) continue;
                const uint32_t ref = pack::detail::page_child_ref(node, s);
                const uint32_t first = (ref & ~pack::detail::kPageLeafRef) >> 2, count = ref & 3u;
                ASSERT_GE(count, 1u);
                ASSERT_LE(count, kPageLeafQuads);
                const Box3f box = cwbvh_child_box(node, s);
                for (uint32_t q = first; q < first + count; ++q) {
                    ++leaf_of_quad[q];
                    for (const auto& v : g.quads[q].v)
                        for (int a = 0; a < 3; ++a) {
                            ASSERT_GE(float(v[a]), box.lo[a]);
                            ASSERT_LE(float(v[a]), box.hi[a]);
                        }
                }
            }
        }
        for (uint32_t q = 0; q < g.quad_count; ++q) ASSERT_EQ(leaf_of_quad[q], 1) << "page " << p << " quad " << q;
    }
}

// The traversal (either top level, the page BVHs, restarts) finds exactly
// what brute force over the same pages finds, with a roomy cache and with a
// cache of one geometry page (every page evicted and reloaded in turn).
class PagedTopLevels : public ::testing::TestWithParam<TopLevel> {};

TEST_P(PagedTopLevels, HitsEqualBruteForceOverTheSamePagesUnderAnyBudget) {
    const PagedFixture& f = fixture(AttributeFormat::Full, GetParam());
    auto file = std::make_shared<const PackFile>(f.path);
    EXPECT_EQ(file->resident().top_level, GetParam());
    EXPECT_EQ(file->top_nodes().empty(), GetParam() == TopLevel::Grid);
    const auto pages = read_all_geometry(*file);
    const std::vector<Ray> rays = test::make_rays(f.geometry, 1200, 7);
    std::vector<Hit> expected(rays.size());
    std::vector<uint32_t> expected_instance(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) expected[i] = brute_force(*file, pages, rays[i], &expected_instance[i]);
    size_t found_instanced = 0;

    size_t slot = 0;
    for (const auto& p : pages) slot = std::max(slot, p.size());
    const auto slots = [&](size_t k) {
        return pages.size() * PageCache::kTableBytesPerPage + k * (slot + PageCache::kBookkeepingBytesPerSlot);
    };
    for (size_t geometry_budget : {size_t(64) << 20, slots(1), slots(3), slots(pages.size() / 4)}) {
        PagedEngine engine(file, {geometry_budget, size_t(1) << 20}, 0);
        std::vector<Hit> hits(rays.size());
        std::vector<uint32_t> instances(rays.size());
        engine.intersect(rays, hits, instances);
        std::vector<uint8_t> blocked(rays.size());
        engine.occluded(rays, blocked);
        size_t found = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            ASSERT_EQ(hits[i].found(), expected[i].found()) << "ray " << i << " budget " << geometry_budget;
            ASSERT_EQ(bool(blocked[i]), expected[i].found()) << "ray " << i;
            if (!expected[i].found()) continue;
            ++found;
            ASSERT_EQ(hits[i].t, expected[i].t) << "ray " << i;
            found_instanced += expected_instance[i] != kNoInstance ? 1 : 0;
            // Equally close triangles aside, the same instance.
            if (hits[i].prim == expected[i].prim) ASSERT_EQ(instances[i], expected_instance[i]) << "ray " << i;
        }
        EXPECT_GT(found, rays.size() / 3);
        EXPECT_LE(engine.geometry_cache().memory_bytes(), geometry_budget);
        if (geometry_budget == slots(1)) {
            // A ray waiting for a page sits out the iterations that bring it nothing:
            // far fewer runs than rays pending in every iteration.
            const EngineStats& s = engine.stats();
            EXPECT_GT(s.iterations, 20u);
            EXPECT_LT(double(s.ray_iterations), 0.5 * double(s.iterations) * double(rays.size()));
        }
    }
    EXPECT_GT(found_instanced, rays.size() / 10) << "rays hit instanced pages";
}

// Rays starting inside the scene with tmin < 0 (what all-hit queries and
// the Python module may pass): the part behind the origin counts, and the
// SIMD node test's distance keys must still order (they once could not).
TEST_P(PagedTopLevels, RaysWithNegativeTminEqualBruteForce) {
    const PagedFixture& f = fixture(AttributeFormat::Full, GetParam());
    auto file = std::make_shared<const PackFile>(f.path);
    const auto pages = read_all_geometry(*file);
    std::vector<Ray> rays = test::make_rays(f.geometry, 600, 11);
    const float extent = max_component(f.geometry.bounds.extent());
    for (size_t i = 0; i < rays.size(); ++i) {
        const float advance = extent * float(i % 7) / 6.0f;
        rays[i].org = rays[i].org + rays[i].dir * advance;
        rays[i].tmin = -advance;
        rays[i].tmax = i % 3 == 0 ? -0.25f * advance : kInfinity;  // some intervals wholly behind the origin
    }
    PagedEngine engine(file, {size_t(64) << 20, size_t(1) << 20}, 0);
    std::vector<Hit> hits(rays.size());
    std::vector<uint32_t> instances(rays.size());
    engine.intersect(rays, hits, instances);
    std::vector<uint8_t> blocked(rays.size());
    engine.occluded(rays, blocked);
    size_t found = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = brute_force(*file, pages, rays[i], nullptr);
        ASSERT_EQ(hits[i].found(), expected.found()) << "ray " << i;
        ASSERT_EQ(bool(blocked[i]), expected.found()) << "ray " << i;
        if (!expected.found()) continue;
        ++found;
        ASSERT_EQ(hits[i].t, expected.t) << "ray " << i;
    }
    EXPECT_GT(found, rays.size() / 4);
}

INSTANTIATE_TEST_SUITE_P(PagedScene, PagedTopLevels, ::testing::Values(TopLevel::WideBvh, TopLevel::Grid),
                         [](const ::testing::TestParamInfo<TopLevel>& info) {
                             return std::string(info.param == TopLevel::Grid ? "Grid" : "WideBvh");
                         });

// Paged hits are the in-core hits up to quantisation: the same surfaces at
// (nearly) the same distances and with the same shading records.
TEST(PagedScene, PagedHitsMatchInCoreHitsWithinQuantisation) {
    for (AttributeFormat format : {AttributeFormat::Full, AttributeFormat::Compact, AttributeFormat::Shared}) {
        const PagedFixture& f = fixture(format);
        auto file = std::make_shared<const PackFile>(f.path);
        PagedEngine engine(file, {size_t(1) << 20, size_t(1) << 16}, 0);
        const auto accel = build_accel(f.geometry);
        const std::vector<ShadingTriangle> in_core = build_shading_triangles(f.scene, f.geometry);
        std::vector<Ray> rays = test::make_rays(f.geometry, 4000, 11);
        std::vector<Hit> paged(rays.size()), exact(rays.size());
        engine.intersect(rays, paged);
        accel->intersect(rays, exact);
        std::vector<ShadingTriangle> records(rays.size());
        engine.fetch_shading(paged, records);
        const float tolerance = 4.0f * float(f.converted.summary.max_quantisation_error);
        size_t agree = 0, both = 0, same_record = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            if (paged[i].found() != exact[i].found()) continue;
            ++agree;
            if (!exact[i].found()) continue;
            const Vec3f a = rays[i].org + rays[i].dir * paged[i].t, b = rays[i].org + rays[i].dir * exact[i].t;
            if (length(a - b) > tolerance * 50.0f) continue;  // a different surface behind an edge
            ++both;
            const ShadingTriangle& want = in_core[exact[i].prim];
            const ShadingTriangle& got = records[i];
            // The same surface: its material, and a normal within a neighbouring triangle's
            // (a ray within a quantisation step of an edge may take the triangle across it).
            if (got.material == want.material && dot(got.geometric_normal, want.geometric_normal) > 0.95f) ++same_record;
        }
        // Silhouette rays may go either way by a quantisation step; nearly all agree.
        EXPECT_GT(double(agree), 0.995 * double(rays.size())) << "format " << int(format);
        EXPECT_GT(double(same_record), 0.995 * double(both)) << "format " << int(format);
    }
}

// The default file (shared-vertex attributes, meshopt codec) and a Full,
// raw one of the same scene: the same pages, so the same hits; records equal
// but for the stated rounding of the geometric normal and the uv/area ratio.
TEST(PagedScene, SharedAttributesDecodeToTheFullRecords) {
    const PagedFixture& full = fixture(AttributeFormat::Full);
    const PagedFixture& shared = fixture(AttributeFormat::Shared);
    auto full_file = std::make_shared<const PackFile>(full.path);
    auto shared_file = std::make_shared<const PackFile>(shared.path);
    EXPECT_LT(shared_file->header().file_bytes * 3, full_file->header().file_bytes);
    size_t meshopt_pages = 0;
    for (const PageEntry& e : shared_file->directory()) meshopt_pages += e.codec == Codec::Meshopt;
    EXPECT_GT(meshopt_pages, shared_file->header().geometry_pages);  // geometry and attribute pages
    // Tiny caches, so that attribute pages are read, evicted and read again.
    PagedEngine a(full_file, {size_t(1) << 20, size_t(1) << 14}, 0), b(shared_file, {size_t(1) << 20, size_t(1) << 14}, 0);
    std::vector<Ray> rays = test::make_rays(full.geometry, 6000, 5);
    std::vector<Hit> ha(rays.size()), hb(rays.size());
    std::vector<uint32_t> ia(rays.size()), ib(rays.size());
    a.intersect(rays, ha, ia);
    b.intersect(rays, hb, ib);
    std::vector<ShadingTriangle> ra(rays.size()), rb(rays.size());
    a.fetch_shading(ha, ra, ia);
    b.fetch_shading(hb, rb, ib);
    size_t found = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        ASSERT_EQ(ha[i].prim, hb[i].prim) << i;
        ASSERT_EQ(ha[i].t, hb[i].t) << i;
        ASSERT_EQ(ia[i], ib[i]) << i;
        if (!ha[i].found()) continue;
        ++found;
        const ShadingTriangle &x = ra[i], &y = rb[i];
        EXPECT_EQ(x.material, y.material);
        EXPECT_EQ(x.flags, y.flags);
        EXPECT_EQ(x.tangent, y.tangent);
        for (int c = 0; c < 3; ++c) {
            EXPECT_EQ(x.normals[c], y.normals[c]);
            EXPECT_EQ(x.uv[c].x, y.uv[c].x);
            EXPECT_EQ(x.uv[c].y, y.uv[c].y);
        }
        EXPECT_LT(length(x.geometric_normal - y.geometric_normal), 0.06 * 3.14159265 / 180.0) << i;
        EXPECT_NEAR(y.uv_area_ratio, x.uv_area_ratio, 0.0014 * x.uv_area_ratio) << i;
    }
    EXPECT_GT(found, rays.size() / 4);
}

// A generated forest: unique terrain and prototypes, thousands of
// instances. Written with instances, the paged hits are the in-core hits of
// the same scene (instances expanded) up to quantisation, with each hit's
// instance reported and its record in world space; the file holds each
// prototype once.
TEST(PagedScene, GeneratedForestInstancesMatchInCore) {
    GenerateOptions g;
    g.name = "forest";
    g.triangles = 20'000;
    g.instanced_triangles = 400'000;
    const std::string path = test::temp_dir("paged_forest") + "/forest.rfpack";
    const PagedWriteReport written = generate_paged_scene(g, path);
    EXPECT_GT(written.instances, 50u);
    EXPECT_GE(written.instanced_triangles, g.instanced_triangles);
    EXPECT_LT(written.triangles, 2 * g.triangles);
    Scene scene = generate_scene(g);
    const SceneGeometry geometry = SceneGeometry::build(scene);
    // In memory: the terrain tiles placed once each, then the prototypes, placed by the instances.
    uint64_t unique = 0, shown_by_instances = 0;
    for (const Mesh& m : scene.meshes) unique += m.triangle_count();
    const size_t first_prototype = scene.meshes.size() - 6;
    for (const Instance& i : scene.instances)
        if (i.mesh >= first_prototype) shown_by_instances += scene.meshes[i.mesh].triangle_count();
    EXPECT_EQ(written.triangles, unique);
    EXPECT_EQ(written.instanced_triangles, shown_by_instances);
    EXPECT_EQ(scene.instances.size() - written.instances, first_prototype);
    auto file = std::make_shared<const PackFile>(path);
    EXPECT_EQ(file->instances().size(), written.instances);
    PagedEngine engine(file, {size_t(1) << 30, size_t(1) << 30}, 0);
    const auto accel = build_accel(geometry);
    const std::vector<ShadingTriangle> in_core = build_shading_triangles(scene, geometry);
    const std::vector<Ray> rays = test::make_rays(geometry, 3000, 5);
    std::vector<Hit> paged(rays.size()), exact(rays.size());
    std::vector<uint32_t> instances(rays.size());
    engine.intersect(rays, paged, instances);
    accel->intersect(rays, exact);
    std::vector<ShadingTriangle> records(rays.size());
    engine.fetch_shading(paged, records, instances);
    const float tolerance = 50.0f * 4.0f * float(written.max_quantisation_error);
    size_t agree = 0, both = 0, instanced = 0, same_normal = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        if (paged[i].found() != exact[i].found()) continue;
        ++agree;
        if (!exact[i].found()) continue;
        const Vec3f a = rays[i].org + rays[i].dir * paged[i].t, b = rays[i].org + rays[i].dir * exact[i].t;
        if (length(a - b) > tolerance) continue;
        ++both;
        instanced += instances[i] != kNoInstance ? 1 : 0;
        if (dot(records[i].geometric_normal, in_core[exact[i].prim].geometric_normal) > 0.95f) ++same_normal;
    }
    EXPECT_GT(double(agree), 0.995 * double(rays.size()));
    EXPECT_GT(double(same_normal), 0.99 * double(both));
    EXPECT_GT(instanced, both / 20) << "rays reach the instances";
}

// Instances are placed only through instanced objects, with finite, invertible transforms.
TEST(PagedScene, WriterRefusesBadInstances) {
    const std::string dir = test::temp_dir("paged_bad_instances");
    PackWriter writer(dir + "/x.rfpack");
    writer.add_material(ShadingMaterial::from(Material{}));
    const std::vector<Vec3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    const std::vector<uint32_t> idx = {0, 1, 2};
    const std::vector<ShadingTriangle> shading(1);
    const uint32_t world = writer.add_object({p, idx, shading});
    const uint32_t object = writer.add_instanced_object({p, idx, shading});
    EXPECT_THROW(writer.add_instance(world, Affine3f::identity()), Error);
    EXPECT_THROW(writer.add_instance(object + 1, Affine3f::identity()), Error);
    EXPECT_THROW(writer.add_instance(object, Affine3f::scale(Vec3f(1, 0, 1))), Error);
    Affine3f nan = Affine3f::identity();
    nan.m[1][3] = NAN;
    EXPECT_THROW(writer.add_instance(object, nan), Error);
    writer.add_instance(object, Affine3f::translation(Vec3f(2, 0, 0)));
    const PackSummary summary = writer.finish();
    EXPECT_EQ(summary.instances, 1u);
    EXPECT_EQ(summary.instanced_triangles, 1u);
    EXPECT_EQ(summary.triangles, 2u);
    const PackFile file(dir + "/x.rfpack");
    EXPECT_EQ(file.top_refs().size(), 2u);
}

std::vector<uint8_t> file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void write_bytes(const std::string& path, const std::vector<uint8_t>& bytes) {
    std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

std::string open_error(const std::string& path) {
    try {
        PackFile file(path);
        return "";
    } catch (const Error& e) {
        return e.what();
    }
}

// The budget's shares: a share larger than its manager can use (all its
// pages at once) passes the rest on, so a small scene under a large budget
// holds every page of every kind; a share that was given stays as given;
// and a budget the machine cannot hold is refused when the file is opened.
TEST(PagedScene, UnusedBudgetSharesGoToTheOtherCaches) {
    const PagedFixture& f = fixture();
    const PackFile file(f.path);
    const FileHeader& h = file.header();
    const uint64_t geometry_all = PageCache::budget_for_all(h.geometry_pages, largest_raw_page(file, 0, h.geometry_pages));
    const uint64_t attributes_all = PageCache::budget_for_all(h.attribute_pages, file.resident().attribute_page_bytes);
    ASSERT_EQ(h.texture_pages, 0u);
    auto caches_of = [&](const PagedSceneOptions& o) { return open_paged_scene(f.path, o)->caches(); };

    // Everything fits: each share shrinks to what its manager can use.
    PagedSceneOptions large;
    large.memory_budget = size_t(1) << 30;
    std::vector<PageCacheReport> c = caches_of(large);
    EXPECT_EQ(c[0].budget_bytes, geometry_all);
    EXPECT_EQ(c[1].budget_bytes, attributes_all);
    EXPECT_EQ(c[0].slots, h.geometry_pages);
    EXPECT_EQ(c[1].slots, h.attribute_pages);

    // Geometry's 80 % is more than it can use, attributes' 20 % less: the
    // attributes get geometry's surplus (up to their own need).
    PagedSceneOptions tight;
    tight.memory_budget = size_t(double(geometry_all) / 0.8 * 1.02);
    ASSERT_LT(0.2 * double(tight.memory_budget), double(attributes_all));
    c = caches_of(tight);
    EXPECT_EQ(c[0].budget_bytes, geometry_all);
    const double expected = std::min(double(attributes_all), double(tight.memory_budget) - double(geometry_all));
    EXPECT_NEAR(double(c[1].budget_bytes), expected, 2.0);
    EXPECT_GT(c[1].budget_bytes, size_t(0.2 * double(tight.memory_budget)));

    // A given share is kept as given, even when the other one has room.
    PagedSceneOptions given = tight;
    given.attribute_budget = size_t(64) << 10;
    c = caches_of(given);
    EXPECT_EQ(c[1].budget_bytes, size_t(64) << 10);

    // More than the machine has: refused when opened, with the numbers.
    const size_t previous = set_memory_budget(size_t(1) << 20);
    try {
        (void)open_paged_scene(f.path, large);
        ADD_FAILURE() << "a budget over the memory available was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("more than the 1 MiB of memory available"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("--memory-budget"), std::string::npos) << e.what();
    }
    set_memory_budget(previous);
}

// The seed's any-hit rule (§6.3.3): a shadow ray tests every cached page
// before asking for a missing one. Here the ray crosses the box of a frame
// (not cached; the ray passes through its hole) before a cached wall that
// blocks it: the wall answers, and the frame's page is never read.
TEST(PagedScene, ShadowRaysBlockedByCachedPagesLoadNothing) {
    Scene scene;
    scene.materials.push_back(Material{});
    auto add_quads = [&](const std::vector<std::array<Vec3f, 4>>& quads) {
        Mesh mesh;
        for (const auto& q : quads) {
            const uint32_t base = uint32_t(mesh.positions.size());
            mesh.positions.insert(mesh.positions.end(), q.begin(), q.end());
            mesh.indices.insert(mesh.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
        }
        mesh.material_ids.assign(mesh.triangle_count(), 0);
        scene.instances.push_back({uint32_t(scene.meshes.size()), Affine3f::identity()});
        scene.meshes.push_back(std::move(mesh));
    };
    // A square frame at z = 0 around a hole of [-1, 1]^2, and a wall at z = -5.
    add_quads({{Vec3f(-2, -2, 0), Vec3f(2, -2, 0), Vec3f(2, -1, 0), Vec3f(-2, -1, 0)},
               {Vec3f(-2, 1, 0), Vec3f(2, 1, 0), Vec3f(2, 2, 0), Vec3f(-2, 2, 0)},
               {Vec3f(-2, -1, 0), Vec3f(-1, -1, 0), Vec3f(-1, 1, 0), Vec3f(-2, 1, 0)},
               {Vec3f(1, -1, 0), Vec3f(2, -1, 0), Vec3f(2, 1, 0), Vec3f(1, 1, 0)}});
    add_quads({{Vec3f(-4, -4, -5), Vec3f(4, -4, -5), Vec3f(4, 4, -5), Vec3f(-4, 4, -5)}});
    scene.finalize();
    const std::string path = test::temp_dir("paged_any_hit") + "/frame.rfpack";
    (void)convert_scene(scene, path, PackWriterOptions{});
    auto file = std::make_shared<const PackFile>(path);
    ASSERT_EQ(file->header().geometry_pages, 2u);
    PagedEngine engine(file, {size_t(64) << 20, size_t(1) << 20}, 0);
    const Vec3f down(0.0f, 0.0f, -1.0f);
    // Cache the wall alone: a ray beside the frame's box.
    std::vector<Hit> hits(1);
    engine.intersect(std::vector<Ray>{{Vec3f(3.5f, 3.5f, 5.0f), 0.0f, down, kInfinity}}, hits);
    ASSERT_TRUE(hits[0].found());
    ASSERT_EQ(engine.geometry_cache().stats().pages_read, 1u);
    engine.geometry_cache().reset_stats();
    // Through the frame's hole to the wall: blocked by the cached wall, nothing read.
    std::vector<uint8_t> blocked(1);
    engine.occluded(std::vector<Ray>{{Vec3f(0.0f, 0.0f, 5.0f), 0.0f, down, 20.0f}}, blocked);
    EXPECT_EQ(blocked[0], 1);
    EXPECT_EQ(engine.geometry_cache().stats().pages_read, 0u);
    // A shadow ray that only the missing frame can block still loads it and is blocked.
    engine.occluded(std::vector<Ray>{{Vec3f(1.5f, 0.0f, 5.0f), 0.0f, down, 6.0f}}, blocked);
    EXPECT_EQ(blocked[0], 1);
    EXPECT_EQ(engine.geometry_cache().stats().pages_read, 1u);
}

// Seams between pages: rays from inside a closed icosphere, paged 64 quads
// a page (169 pages), aimed at every vertex and edge midpoint. The pages
// share one quantisation lattice, so a vertex two pages share decodes to the
// same point in both (page_builder.h), and each page's triangles are tested
// in world space: the paged rays hit exactly where the same rays hit the
// decoded triangles in core, one mesh, nothing leaking at a seam. (With a
// cube per page 3,338 of the 71,682 rays, 4.7 %, passed through the seams;
// with the lattice and the tests in page space, 25.) The decoded mesh itself
// misses 3: quantisation moved a vertex onto an edge (a T-junction), which
// no watertight test closes; the input mesh misses none.
TEST(PagedScene, RaysAtPageSeamsNeverLeak) {
    const test::IndexedMesh sphere = test::make_icosphere(5);
    Scene scene;
    scene.materials.push_back(Material{});
    Mesh mesh;
    mesh.positions = sphere.positions;
    mesh.indices = sphere.indices;
    mesh.material_ids.assign(mesh.triangle_count(), 0);
    scene.meshes.push_back(std::move(mesh));
    scene.instances.push_back({0, Affine3f::identity()});
    scene.finalize();
    const std::string path = test::temp_dir("paged_seams") + "/sphere.rfpack";
    PackWriterOptions options;
    options.quads_per_page = 64;
    (void)convert_scene(scene, path, options);
    auto file = std::make_shared<const PackFile>(path);
    PagedEngine engine(file, {size_t(256) << 20, size_t(64) << 20}, 0);
    std::vector<Ray> rays;
    const Vec3f origin(0.013f, -0.021f, 0.017f);  // inside, off the centre
    auto aim = [&](Vec3f target) { rays.push_back({origin, 0.0f, target - origin, kInfinity}); };
    for (const Vec3f& p : sphere.positions) aim(p);
    for (size_t i = 0; i < sphere.indices.size(); i += 3) {
        for (int k = 0; k < 3; ++k) {
            const Vec3f a = sphere.positions[sphere.indices[i + k]], b = sphere.positions[sphere.indices[i + (k + 1) % 3]];
            aim((a + b) * 0.5f);
        }
    }
    std::vector<Hit> hits(rays.size());
    engine.intersect(rays, hits);
    std::vector<size_t> leaks;
    for (size_t i = 0; i < hits.size(); ++i)
        if (!hits[i].found()) leaks.push_back(i);
    // The same rays in core: over the input triangles, and over the paged
    // file's decoded triangles (each page's own quantisation).
    auto misses_in_core = [&](const SceneGeometry& g) {
        const auto accel = build_accel(g);
        std::vector<Hit> h(rays.size());
        accel->intersect(rays, h);
        std::vector<size_t> missed;
        for (size_t i = 0; i < h.size(); ++i)
            if (!h[i].found()) missed.push_back(i);
        return missed;
    };
    const size_t input_misses = misses_in_core(SceneGeometry::build(scene)).size();
    const std::vector<size_t> decoded_misses = misses_in_core(decode_paged_geometry(path).geometry);
    EXPECT_GT(file->header().geometry_pages, 100u);
    EXPECT_EQ(input_misses, 0u);
    EXPECT_LE(decoded_misses.size(), 10u);  // T-junctions of the quantised mesh
    EXPECT_EQ(leaks, decoded_misses) << "of " << rays.size() << " rays at vertices and edge midpoints";
}

TEST(PagedScene, TruncatedAndCorruptedFilesGiveOneLineErrors) {
    const PagedFixture& f = fixture();
    const std::string dir = test::temp_dir("paged_corrupt");
    const std::vector<uint8_t> good = file_bytes(f.path);

    std::vector<uint8_t> truncated(good.begin(), good.begin() + long(good.size() / 2));
    write_bytes(dir + "/truncated.rfpack", truncated);
    EXPECT_NE(open_error(dir + "/truncated.rfpack").find("truncated"), std::string::npos);

    write_bytes(dir + "/tiny.rfpack", std::vector<uint8_t>(good.begin(), good.begin() + 40));
    EXPECT_NE(open_error(dir + "/tiny.rfpack").find("shorter than its header"), std::string::npos);

    std::vector<uint8_t> bad_magic = good;
    bad_magic[0] = 'X';
    write_bytes(dir + "/magic.rfpack", bad_magic);
    EXPECT_NE(open_error(dir + "/magic.rfpack").find("bad magic"), std::string::npos);

    const PackFile file(f.path);
    std::vector<uint8_t> bad_resident = good;
    bad_resident[file.header().resident_offset + 50] ^= 0x40;
    write_bytes(dir + "/resident.rfpack", bad_resident);
    EXPECT_NE(open_error(dir + "/resident.rfpack").find("checksum"), std::string::npos);

    // A flipped byte inside a page: the file opens, the page read fails.
    std::vector<uint8_t> bad_page = good;
    bad_page[file.directory()[3].offset + 100] ^= 0x01;
    write_bytes(dir + "/page.rfpack", bad_page);
    const PackFile opened(dir + "/page.rfpack");
    std::vector<uint8_t> out, scratch;
    EXPECT_NO_THROW(opened.read_page(2, out, scratch));
    try {
        opened.read_page(3, out, scratch);
        FAIL() << "a corrupted page was read";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("page 3 checksum mismatch"), std::string::npos) << e.what();
    }

    // Version 1 (binary page BVHs) and 2 (per-triangle attribute records
    // only) files are refused with what to do.
    for (uint32_t version : {1u, 2u}) {
        std::vector<uint8_t> old_version = good;
        FileHeader header;
        std::memcpy(&header, old_version.data(), sizeof(header));
        header.version = version;
        header.header_checksum = crc32c(&header, offsetof(FileHeader, header_checksum));
        std::memcpy(old_version.data(), &header, sizeof(header));
        const std::string old_path = dir + "/v" + std::to_string(version) + ".rfpack";
        write_bytes(old_path, old_version);
        const std::string expected =
            "version " + std::to_string(version) + " (this rayforge reads version 3; convert the scene again)";
        EXPECT_NE(open_error(old_path).find(expected), std::string::npos) << open_error(old_path);
    }
}

// Wide trees in pages and in the resident top level come from files: a tree
// that would send the traversal out of its arrays, around a cycle, twice
// through a node or past its stack is refused, naming the node.
TEST(PagedScene, MalformedWideTreesAreRefused) {
    const PagedFixture& f = fixture();
    const PackFile file(f.path);
    // The page with the most nodes.
    const auto pages = read_all_geometry(file);
    size_t largest = 0;
    for (size_t p = 0; p < pages.size(); ++p)
        if (pages[p].size() > pages[largest].size()) largest = p;
    const GeometryPageView view = view_geometry_page(pages[largest], "page");
    ASSERT_GT(view.node_count, 1u);
    const std::vector<PageNode> good(view.nodes, view.nodes + view.node_count);
    EXPECT_EQ(check_wide_tree(good.data(), view.node_count, view.quad_count), "");
    const auto problem = [&](auto&& edit) {
        std::vector<PageNode> nodes = good;
        edit(nodes);
        return check_wide_tree(nodes.data(), uint32_t(nodes.size()), view.quad_count);
    };
    const int inner = [&] {
        for (int s = 0; s < kCwbvhWidth; ++s)
            if (cwbvh_meta_is_inner(good[0].meta[s])) return s;
        return -1;
    }();
    ASSERT_GE(inner, 0);
    EXPECT_NE(problem([](auto& n) { n[0].base_index_child = 0; }).find("before it"), std::string::npos);
    EXPECT_NE(problem([](auto& n) { n[0].base_index_child = uint32_t(n.size()); }).find("outside the page"), std::string::npos);
    EXPECT_NE(problem([&](auto& n) { n[0].imask = uint8_t(n[0].imask ^ (1u << inner)); }).find("inner mask"),
              std::string::npos);
    EXPECT_NE(problem([&](auto& n) { n[0].meta[inner] = uint8_t(0x20u | 3u); }).find("node 0"), std::string::npos);
    // A leaf slot pointing past the quads.
    for (uint32_t i = 0; i < good.size(); ++i)
        for (int s = 0; s < kCwbvhWidth; ++s)
            if (good[i].meta[s] != kCwbvhEmptyMeta && !cwbvh_meta_is_inner(good[i].meta[s])) {
                EXPECT_NE(problem([&](auto& n) { n[i].base_index_triangle = view.quad_count; }).find("past its items"),
                          std::string::npos);
                i = uint32_t(good.size());
                break;
            }
    // Two parents for one node (node 1 also the child of its last inner sibling's slot).
    std::vector<PageNode> chain(3);
    for (auto& n : chain) n = PageNode{};
    chain[0].imask = 0b11;
    chain[0].meta[0] = cwbvh_inner_meta(0);
    chain[0].meta[1] = cwbvh_inner_meta(1);
    chain[0].base_index_child = 1;
    chain[1].meta[0] = cwbvh_leaf_meta(1, 0);
    chain[2].meta[0] = cwbvh_leaf_meta(1, 0);
    EXPECT_EQ(check_wide_tree(chain.data(), 3, 1), "");
    chain[1].imask = 0b1;
    chain[1].meta[0] = cwbvh_inner_meta(0);
    chain[1].base_index_child = 2;
    EXPECT_NE(check_wide_tree(chain.data(), 3, 1).find("two parents"), std::string::npos);
    // Deeper than the traversal's stack: a chain of kCwbvhMaxDepth + 1 nodes (kCwbvhMaxDepth pass).
    const auto chain_of = [](uint32_t length) {
        std::vector<PageNode> nodes(length);
        for (uint32_t i = 0; i < length; ++i) {
            nodes[i] = PageNode{};
            if (i + 1 < length) {
                nodes[i].imask = 1;
                nodes[i].meta[0] = cwbvh_inner_meta(0);
                nodes[i].base_index_child = i + 1;
            } else {
                nodes[i].meta[0] = cwbvh_leaf_meta(1, 0);
            }
        }
        return nodes;
    };
    const std::vector<PageNode> deepest = chain_of(kCwbvhMaxDepth), too_deep = chain_of(kCwbvhMaxDepth + 1);
    EXPECT_EQ(check_wide_tree(deepest.data(), uint32_t(deepest.size()), 1), "");
    EXPECT_NE(check_wide_tree(too_deep.data(), uint32_t(too_deep.size()), 1).find("deeper than"), std::string::npos);
}

}  // namespace
}  // namespace rf
