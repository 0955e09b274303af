// The benchmark harness itself: identical ray sets on every run, the tree
// quality metrics on hand-built BVHs, the Embree adapter against brute
// force, candidate selection, views.json parsing and the `bench` command.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include <nlohmann/json.hpp>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "accel_test_scenes.h"
#include "bench_runner.h"
#include "bench_scenes.h"
#include "candidates.h"
#include "core/parallel.h"
#include "bench_report.h"
#include "embree_peer.h"
#include "device_build_report.h"
#include "gpu_candidates.h"
#include "presets.h"
#include "ray_sets.h"
#include "render_bench.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

using bench::RaySetKind;

bool same_bits(const std::vector<Ray>& a, const std::vector<Ray>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Ray)) == 0);
}

struct CornellFixture {
    Scene scene = make_builtin_scene("cornell");
    SceneGeometry geometry = SceneGeometry::build(scene);
};

bench::ViewSetup small_view(const Scene& scene) {
    bench::ViewSetup view;
    view.camera = scene.camera_or_default();
    view.width = 64;
    view.height = 48;
    view.light = {0.0f, 1.5f, 0.0f};
    view.ao_radius = 0.5f;
    return view;
}

TEST(BenchRaySets, GenerationIsDeterministicAcrossRunsAndThreadCounts) {
    CornellFixture f;
    const auto accel = build_accel(f.geometry);
    const bench::ViewSetup view = small_view(f.scene);
    const std::vector<RaySetKind> kinds(std::begin(bench::kAllRaySets), std::end(bench::kAllRaySets));
    const auto one = parallel::with_threads(1, [&] { return bench::make_ray_sets(f.geometry, *accel, view, kinds); });
    const auto two = parallel::with_threads(2, [&] { return bench::make_ray_sets(f.geometry, *accel, view, kinds); });
    const auto again = bench::make_ray_sets(f.geometry, *accel, view, kinds);
    ASSERT_EQ(one.size(), kinds.size());
    for (size_t i = 0; i < kinds.size(); ++i) {
        EXPECT_EQ(one[i].kind, kinds[i]);
        EXPECT_FALSE(one[i].rays.empty()) << bench::ray_set_name(kinds[i]);
        EXPECT_TRUE(same_bits(one[i].rays, two[i].rays)) << bench::ray_set_name(kinds[i]);
        EXPECT_TRUE(same_bits(one[i].rays, again[i].rays)) << bench::ray_set_name(kinds[i]);
    }
    // A different view gives different rays (the test above can fail).
    bench::ViewSetup other = view;
    other.light = {0.1f, 1.5f, 0.0f};
    const auto moved = bench::make_ray_sets(f.geometry, *accel, other, {RaySetKind::Shadow});
    EXPECT_FALSE(same_bits(moved[0].rays, one[1].rays));
}

TEST(BenchRaySets, RaysFollowTheProtocol) {
    CornellFixture f;
    const auto accel = build_accel(f.geometry);
    const bench::ViewSetup view = small_view(f.scene);
    const auto sets = bench::make_ray_sets(f.geometry, *accel, view,
                                           {RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Ao,
                                            RaySetKind::Diffuse, RaySetKind::Reflection});
    const auto& primary = sets[0].rays;
    ASSERT_EQ(primary.size(), size_t(64 * 48));
    std::vector<Hit> hits(primary.size());
    accel->intersect(primary, hits);
    size_t hit_count = 0;
    for (const Hit& h : hits) hit_count += h.found() ? 1 : 0;
    ASSERT_GT(hit_count, 0u);
    EXPECT_EQ(sets[1].rays.size(), hit_count);
    EXPECT_EQ(sets[2].rays.size(), hit_count * bench::kAoSamplesPerHit);
    EXPECT_EQ(sets[3].rays.size(), hit_count * bench::kAoSamplesPerHit);
    EXPECT_EQ(sets[4].rays.size(), hit_count);

    const float offset = 1e-4f * length(f.geometry.bounds.extent());
    size_t slot = 0;
    for (size_t p = 0; p < hits.size(); ++p) {
        if (!hits[p].found()) continue;
        const Vec3f point = primary[p].org + primary[p].dir * hits[p].t;
        Vec3f n = normalize(f.geometry.triangles[hits[p].prim].geometric_normal());
        if (dot(n, primary[p].dir) > 0.0f) n = -n;
        const Ray& shadow = sets[1].rays[slot];
        EXPECT_NEAR(length(shadow.org - point), offset, 1e-3f * offset + 1e-6f);
        EXPECT_NEAR(shadow.tmax, length(view.light - shadow.org), 1e-4f);
        EXPECT_NEAR(length(shadow.dir), 1.0f, 1e-5f);
        for (int s = 0; s < bench::kAoSamplesPerHit; ++s) {
            const Ray& ao = sets[2].rays[slot * bench::kAoSamplesPerHit + size_t(s)];
            const Ray& diffuse = sets[3].rays[slot * bench::kAoSamplesPerHit + size_t(s)];
            EXPECT_GE(dot(ao.dir, n), -1e-5f);  // in the hemisphere facing the viewer
            EXPECT_FLOAT_EQ(ao.tmax, view.ao_radius);
            EXPECT_EQ(diffuse.tmax, kInfinity);
            EXPECT_EQ(ao.dir.x, diffuse.dir.x);
        }
        const Ray& reflection = sets[4].rays[slot];
        EXPECT_NEAR(dot(reflection.dir, n), -dot(primary[p].dir, n), 1e-4f);  // mirror angle
        ++slot;
    }
}

// The protocol's GPU rule: spp jittered camera samples per pixel, sample-major,
// sample 0 at the pixel centre, so the first pixel-count rays (and the
// secondary rays derived from them) are exactly the one-sample sets.
TEST(BenchRaySets, SamplesPerPixelExtendTheOneSampleSets) {
    CornellFixture f;
    const auto accel = build_accel(f.geometry);
    bench::ViewSetup view = small_view(f.scene);
    const std::vector<RaySetKind> kinds(std::begin(bench::kAllRaySets), std::end(bench::kAllRaySets));
    const auto one = bench::make_ray_sets(f.geometry, *accel, view, kinds);
    view.samples_per_pixel = 4;
    const auto four = bench::make_ray_sets(f.geometry, *accel, view, kinds);
    ASSERT_EQ(four.size(), kinds.size());
    const size_t pixels = size_t(view.width) * size_t(view.height);
    ASSERT_EQ(four[0].rays.size(), 4 * pixels);
    ASSERT_EQ(one[0].rays.size(), pixels);

    // Hits among the 4-sample primaries decide the secondary sizes.
    std::vector<Hit> hits(four[0].rays.size());
    accel->intersect(four[0].rays, hits);
    size_t hit_count = 0, hits_of_sample0 = 0;
    for (size_t i = 0; i < hits.size(); ++i) {
        hit_count += hits[i].found() ? 1 : 0;
        if (i < pixels) hits_of_sample0 += hits[i].found() ? 1 : 0;
    }
    ASSERT_GT(hits_of_sample0, pixels / 2);  // the camera looks into the box
    for (size_t k = 0; k < kinds.size(); ++k) {
        const size_t per_hit = (kinds[k] == RaySetKind::Ao || kinds[k] == RaySetKind::Diffuse) ? bench::kAoSamplesPerHit : 1;
        const size_t expected = kinds[k] == RaySetKind::Primary ? 4 * pixels : per_hit * hit_count;
        EXPECT_EQ(four[k].rays.size(), expected) << bench::ray_set_name(kinds[k]);
        // Sample 0 comes first and is bit for bit the one-sample set.
        ASSERT_LE(one[k].rays.size(), four[k].rays.size());
        const std::vector<Ray> prefix(four[k].rays.begin(), four[k].rays.begin() + std::ptrdiff_t(one[k].rays.size()));
        EXPECT_TRUE(same_bits(prefix, one[k].rays)) << bench::ray_set_name(kinds[k]);
    }
    // Every jittered secondary ray differs from the one-sample rays (new samples, new directions).
    const std::vector<Ray>& ao = four[2].rays;
    const size_t first_jittered = one[2].rays.size();
    ASSERT_GT(ao.size(), first_jittered);
    EXPECT_FALSE(std::memcmp(&ao[first_jittered], &ao[0], sizeof(Ray)) == 0);
}

TEST(BenchRaySets, JitteredSamplesStayInsideTheirPixel) {
    CornellFixture f;
    bench::ViewSetup view = small_view(f.scene);
    view.samples_per_pixel = 4;
    const bench::RaySet primary = bench::make_primary_rays(view);
    const CameraFrame frame = CameraFrame::make(view.camera, view.width, view.height);
    const size_t pixels = size_t(view.width) * size_t(view.height);
    ASSERT_EQ(primary.rays.size(), 4 * pixels);
    // Inverts CameraFrame::generate: the film position the ray passes through.
    const float tolerance = 1e-3f;  // pixels; float rounding of the direction
    size_t off_centre = 0;
    double sum_u = 0.0;
    for (size_t i = 0; i < primary.rays.size(); ++i) {
        const size_t sample = i / pixels, pixel = i % pixels;
        const int x = int(pixel % size_t(view.width)), y = int(pixel / size_t(view.width));
        const Ray& ray = primary.rays[i];
        const float along = dot(ray.dir, frame.forward);
        ASSERT_GT(along, 0.0f);
        const float ndc_x = dot(ray.dir, frame.right) / along, ndc_y = dot(ray.dir, frame.up) / along;
        const float px = (ndc_x / (frame.tan_half_fov * frame.aspect) + 1.0f) * 0.5f * float(view.width);
        const float py = (1.0f - ndc_y / frame.tan_half_fov) * 0.5f * float(view.height);
        ASSERT_GE(px, float(x) - tolerance) << "sample " << sample << " pixel " << pixel;
        ASSERT_LE(px, float(x + 1) + tolerance) << "sample " << sample << " pixel " << pixel;
        ASSERT_GE(py, float(y) - tolerance) << "sample " << sample << " pixel " << pixel;
        ASSERT_LE(py, float(y + 1) + tolerance) << "sample " << sample << " pixel " << pixel;
        const Vec2f at = bench::pixel_sample_position(uint32_t(pixel), uint32_t(sample));
        ASSERT_TRUE(at.x >= 0.0f && at.x < 1.0f && at.y >= 0.0f && at.y < 1.0f);
        if (sample == 0) {
            EXPECT_NEAR(px, float(x) + 0.5f, tolerance);
            EXPECT_NEAR(py, float(y) + 0.5f, tolerance);
        } else {
            EXPECT_NEAR(px, float(x) + at.x, tolerance);
            off_centre += (std::fabs(at.x - 0.5f) > 1e-3f || std::fabs(at.y - 0.5f) > 1e-3f) ? 1 : 0;
            sum_u += at.x;
        }
    }
    // The jitter is spread over the pixel: nearly every sample is off centre,
    // and the mean offset of 3 x pixels uniform numbers is 1/2 within 5 sigma
    // (sigma = sqrt(1/12 / n)).
    const double n = 3.0 * double(pixels);
    EXPECT_GT(double(off_centre), 0.99 * n);
    EXPECT_NEAR(sum_u / n, 0.5, 5.0 * std::sqrt(1.0 / 12.0 / n));
}

TEST(BenchRaySets, MortonOrderIsAPermutationInAlignedTiles) {
    for (const auto& [w, h] : std::vector<std::pair<int, int>>{{64, 48}, {13, 7}, {1, 1}, {1, 40}, {1024, 768}}) {
        const std::vector<uint32_t> order = bench::morton_pixel_order(w, h);
        ASSERT_EQ(order.size(), size_t(w) * size_t(h));
        std::vector<uint32_t> sorted = order;
        std::sort(sorted.begin(), sorted.end());
        for (size_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i) << w << "x" << h;
    }
    // Where the sides are multiples of 8 and 4, every warp of 32 is one aligned 8x4 tile.
    const int w = 64, h = 48;
    const std::vector<uint32_t> order = bench::morton_pixel_order(w, h);
    for (size_t warp = 0; warp < order.size() / 32; ++warp) {
        const uint32_t x0 = order[warp * 32] % w, y0 = order[warp * 32] / w;
        EXPECT_EQ(x0 % 8, 0u);
        EXPECT_EQ(y0 % 4, 0u);
        for (size_t lane = 0; lane < 32; ++lane) {
            const uint32_t x = order[warp * 32 + lane] % w, y = order[warp * 32 + lane] / w;
            EXPECT_TRUE(x >= x0 && x < x0 + 8 && y >= y0 && y < y0 + 4) << "warp " << warp << " lane " << lane;
        }
    }
    EXPECT_THROW(bench::morton_pixel_order(0, 4), Error);
}

TEST(BenchRaySets, MortonPrimariesAreTheScanlinePrimariesPermuted) {
    CornellFixture f;
    const auto accel = build_accel(f.geometry);
    bench::ViewSetup view = small_view(f.scene);
    view.width = 37;  // not a power of two, not a multiple of 8
    view.height = 21;
    view.samples_per_pixel = 2;
    const auto sets = bench::make_ray_sets(f.geometry, *accel, view, {RaySetKind::Primary, RaySetKind::PrimaryMorton});
    ASSERT_EQ(sets.size(), 2u);
    EXPECT_EQ(sets[1].kind, RaySetKind::PrimaryMorton);
    const std::vector<Ray>& scan = sets[0].rays;
    const std::vector<Ray>& morton = sets[1].rays;
    ASSERT_EQ(morton.size(), scan.size());
    EXPECT_FALSE(same_bits(morton, scan));  // reordered
    // The same rays as a multiset.
    const auto bytes_less = [](const Ray& a, const Ray& b) { return std::memcmp(&a, &b, sizeof(Ray)) < 0; };
    std::vector<Ray> a = scan, b = morton;
    std::sort(a.begin(), a.end(), bytes_less);
    std::sort(b.begin(), b.end(), bytes_less);
    EXPECT_TRUE(same_bits(a, b));
    // Hits of the Morton set, permuted back, are the scanline set's.
    std::vector<Hit> scan_hits(scan.size()), morton_hits(morton.size());
    accel->intersect(scan, scan_hits);
    accel->intersect(morton, morton_hits);
    const std::vector<uint32_t> order = bench::morton_pixel_order(view.width, view.height);
    const size_t pixels = order.size();
    size_t found = 0;
    for (size_t sample = 0; sample < 2; ++sample)
        for (size_t i = 0; i < pixels; ++i) {
            const Hit& m = morton_hits[sample * pixels + i];
            const Hit& s = scan_hits[sample * pixels + order[i]];
            ASSERT_EQ(m.found(), s.found());
            if (!m.found()) continue;
            ++found;
            EXPECT_EQ(m.prim, s.prim);
            EXPECT_EQ(m.t, s.t);
            EXPECT_EQ(m.u, s.u);
            EXPECT_EQ(m.v, s.v);
        }
    EXPECT_GT(found, pixels / 2);  // most camera rays hit the box
    // A set that is not the view's primaries is refused.
    bench::RaySet wrong = sets[0];
    wrong.rays.pop_back();
    EXPECT_THROW(bench::make_morton_primary_rays(wrong, view), Error);
}

TEST(BenchRaySets, GpuRowsAddMortonPrimariesOnce) {
    using K = RaySetKind;
    EXPECT_EQ(bench::with_morton_primaries({K::Primary, K::Diffuse}),
              (std::vector<K>{K::Primary, K::PrimaryMorton, K::Diffuse}));
    EXPECT_EQ(bench::with_morton_primaries({K::Diffuse}), (std::vector<K>{K::Diffuse}));
    EXPECT_EQ(bench::with_morton_primaries({K::PrimaryMorton, K::Primary}),
              (std::vector<K>{K::PrimaryMorton, K::Primary}));
}

TEST(BenchRaySets, NamesRoundTrip) {
    EXPECT_EQ(bench::parse_ray_set("primary-morton"), RaySetKind::PrimaryMorton);
    EXPECT_FALSE(bench::is_any_hit(RaySetKind::PrimaryMorton));
    for (RaySetKind kind : bench::kAllRaySets) EXPECT_NE(kind, RaySetKind::PrimaryMorton);  // the protocol's five
    for (RaySetKind kind : bench::kAllRaySets) EXPECT_EQ(bench::parse_ray_set(bench::ray_set_name(kind)), kind);
    EXPECT_FALSE(bench::parse_ray_set("primaries").has_value());
    EXPECT_TRUE(bench::is_any_hit(RaySetKind::Shadow));
    EXPECT_TRUE(bench::is_any_hit(RaySetKind::Ao));
    EXPECT_FALSE(bench::is_any_hit(RaySetKind::Diffuse));
}

// Root [0,2]^3 (area 24); left leaf [0,1]^3 (area 6, 2 triangles); right leaf
// [1,2]x[0,2]x[0,2] (area 16, 3 triangles).
Bvh hand_built_bvh() {
    Bvh bvh;
    bvh.nodes.resize(3);
    bvh.nodes[0].bounds = Box3f(Vec3f(0, 0, 0), Vec3f(2, 2, 2));
    bvh.nodes[0].first = 1;
    bvh.nodes[1].bounds = Box3f(Vec3f(0, 0, 0), Vec3f(1, 1, 1));
    bvh.nodes[1].first = 0;
    bvh.nodes[1].count = 2;
    bvh.nodes[2].bounds = Box3f(Vec3f(1, 0, 0), Vec3f(2, 2, 2));
    bvh.nodes[2].first = 2;
    bvh.nodes[2].count = 3;
    bvh.prim_indices = {0, 1, 2, 3, 4};
    return bvh;
}

TEST(BenchMetrics, SahCostOfAHandBuiltBvh) {
    const Bvh bvh = hand_built_bvh();
    // 1 (root) + 6/24 * 2 + 16/24 * 3 = 1 + 0.5 + 2.
    EXPECT_DOUBLE_EQ(bvh.sah_cost(1.0f, 1.0f), 3.5);
    // C_trav = 2, C_int = 3: 2 + 0.5 * 3 + 2 * 3.
    EXPECT_DOUBLE_EQ(bvh.sah_cost(2.0f, 3.0f), 9.5);
}

TEST(BenchMetrics, Formula42OfAHandBuiltBvh) {
    Bvh bvh = hand_built_bvh();
    // C = nc + 6/24 * 2 + 16/24 * 3 = 2 + 0.5 + 2.
    EXPECT_DOUBLE_EQ(bvh.quality_cost(2.0), 4.5);
    // Two levels: split the right leaf into [1,2]x[0,1]x[0,2] (area 10, 1 tri)
    // and [1,2]x[1,2]x[0,2] (area 10, 2 tris): C(right) = 2 + 10/16 + 10/16 * 2.
    bvh.nodes[2].count = 0;
    bvh.nodes[2].first = 3;
    bvh.nodes.resize(5);
    bvh.nodes[3].bounds = Box3f(Vec3f(1, 0, 0), Vec3f(2, 1, 2));
    bvh.nodes[3].first = 2;
    bvh.nodes[3].count = 1;
    bvh.nodes[4].bounds = Box3f(Vec3f(1, 1, 0), Vec3f(2, 2, 2));
    bvh.nodes[4].first = 3;
    bvh.nodes[4].count = 2;
    const double right = 2.0 + 10.0 / 16.0 + 10.0 / 16.0 * 2.0;
    EXPECT_DOUBLE_EQ(bvh.quality_cost(2.0), 2.0 + 0.5 + 16.0 / 24.0 * right);
    // Unrolled, formula 4.2 is the SAH with C_trav = nc, C_int = 1.
    EXPECT_NEAR(bvh.quality_cost(2.0), bvh.sah_cost(2.0f, 1.0f), 1e-12);
}

TEST(BenchMetrics, Formula42MatchesSahOnABuiltTree) {
    const SceneGeometry geometry = test::make_triangle_soup(5000, 7, Box3f(Vec3f(-10.0f), Vec3f(10.0f)), 0.5f);
    const BvhAccel accel(geometry, build_bvh(geometry.triangles, BuildOptions{}), "bvh/binned/bvh2", 0.0);
    const AccelStats stats = accel.stats();
    EXPECT_NEAR(stats.quality_cost, accel.bvh().sah_cost(2.0f, 1.0f), 1e-6 * stats.quality_cost);
    EXPECT_GT(stats.quality_cost, stats.sah_cost);
}

TEST(BenchMetrics, MedianAndHitComparison) {
    EXPECT_DOUBLE_EQ(bench::median({5, 1, 3}), 3.0);
    EXPECT_DOUBLE_EQ(bench::median({4, 1, 3, 2}), 2.5);
    std::vector<Hit> a(4), b(4);
    a[0].prim = b[0].prim = 1;
    a[0].t = 1.0f;
    b[0].t = 1.001f;
    a[1].prim = 2;  // hit vs miss
    a[1].t = 2.0f;
    a[2].prim = 3;  // different primitive
    b[2].prim = 4;
    a[2].t = b[2].t = 3.0f;
    double agreement = 0, max_dt = 0;
    bench::compare_hits(a, b, agreement, max_dt);
    EXPECT_DOUBLE_EQ(agreement, 0.5);  // rays 0 and 3 (both miss)
    EXPECT_NEAR(max_dt, 0.001 / 1.001, 1e-6);
}

TEST(BenchEmbree, AgreesWithBruteForce) {
    if (!bench::embree_available()) GTEST_SKIP() << "rayforge built without Embree";
    const SceneGeometry geometry = test::make_triangle_soup(3000, 11, Box3f(Vec3f(-5.0f), Vec3f(5.0f)), 0.8f);
    const auto brute = build_accel(geometry, BuildOptions{.structure = Structure::BruteForce});
    std::mt19937 rng(5);
    std::vector<Ray> rays(4000);
    for (Ray& ray : rays) {
        ray.org = test::random_in_box(rng, Box3f(Vec3f(-7.0f), Vec3f(7.0f)));
        ray.dir = test::random_direction(rng);
    }
    for (size_t i = 0; i < rays.size(); i += 2) rays[i].tmax = 3.0f;  // bounded rays too
    std::vector<Hit> expected(rays.size());
    brute->intersect(rays, expected);
    std::vector<uint8_t> expected_occluded(rays.size());
    brute->occluded(rays, expected_occluded);
    size_t hits = 0;
    for (const Hit& h : expected) hits += h.found() ? 1 : 0;
    ASSERT_GT(hits, rays.size() / 10);

    for (bench::EmbreeQuality quality : bench::kAllEmbreeQualities) {
        const bench::EmbreePeer peer(geometry, quality, 2);
        std::vector<Hit> got(rays.size());
        peer.intersect(rays, got);
        double agreement = 0, max_dt = 0;
        bench::compare_hits(expected, got, agreement, max_dt);
        // Embree's (non-watertight) test may differ on a grazing edge hit or two.
        EXPECT_GE(agreement, 0.999) << bench::embree_quality_name(quality);
        EXPECT_LT(max_dt, 1e-4) << bench::embree_quality_name(quality);
        for (size_t i = 0; i < rays.size(); ++i) {
            if (expected[i].found() && got[i].found() && expected[i].prim == got[i].prim) {
                EXPECT_NEAR(got[i].u, expected[i].u, 1e-3f);
                EXPECT_NEAR(got[i].v, expected[i].v, 1e-3f);
            }
        }
        std::vector<uint8_t> occluded(rays.size());
        peer.occluded(rays, occluded);
        size_t same = 0;
        for (size_t i = 0; i < rays.size(); ++i) same += occluded[i] == expected_occluded[i] ? 1 : 0;
        EXPECT_GE(double(same) / double(rays.size()), 0.999) << bench::embree_quality_name(quality);
        EXPECT_GT(peer.build_ms(), 0.0);
    }
}

TEST(BenchCandidates, SelectionNamesWhatIsMissing) {
    std::vector<bench::Candidate> missing;
    const auto chosen = bench::select_candidates({"bvh"}, {"all"}, {"all"}, &missing);
    ASSERT_FALSE(chosen.empty());
    EXPECT_EQ(chosen.front().label(), "bvh/binned/bvh2");
    for (const auto& c : chosen) EXPECT_TRUE(c.implemented);
    for (const auto& c : missing) EXPECT_FALSE(c.implemented);
    // Every bvh candidate in `all` is either chosen or named as missing.
    size_t bvh_in_all = 0;
    for (const auto& c : bench::candidate_catalogue()) bvh_in_all += c.structure == "bvh" && c.in_all;
    EXPECT_EQ(chosen.size() + missing.size(), bvh_in_all);
    // +opt variants come only when their builder is named.
    const auto optimised = bench::select_candidates({"bvh"}, {"binned+opt"}, {"bvh2"}, nullptr);
    ASSERT_EQ(optimised.size(), 1u);
    EXPECT_TRUE(optimised.front().options.reinsertion.enabled);
    // `all` leaves brute force out; naming it brings it in.
    for (const auto& c : bench::select_candidates({"all"}, {"all"}, {"all"}, nullptr))
        EXPECT_NE(c.structure, "brute");
    EXPECT_EQ(bench::select_candidates({"brute"}, {"all"}, {"all"}, nullptr).size(), 1u);
    EXPECT_THROW(bench::select_candidates({"bvh"}, {"binnned"}, {"all"}, nullptr), Error);
    EXPECT_THROW(bench::candidates_by_label({"bvh/nope/bvh2"}, nullptr), Error);
}

TEST(BenchScenes, ViewsJsonIsReadAndCheckedForErrors) {
    const std::string dir = test::temp_dir("bench_views");
    {
        std::ofstream out(dir + "/views.json");
        out << R"({"scenes": {
            "tri": {"file": "tri.obj", "views": [{"eye": [0, 0, 3], "target": [0, 0, 0], "fov": 50}],
                    "light": [1, 2, 3], "ao_radius": 0.25},
            "bad": {"file": "tri.obj", "light": [1, 2]},
            "nofile": {"views": []}}})";
    }
    {
        std::ofstream out(dir + "/tri.obj");
        out << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    }
    EXPECT_EQ(bench::find_scenes_dir(dir), dir);
    EXPECT_THROW(bench::find_scenes_dir(dir + "/missing"), Error);
    const bench::SceneSpec spec = bench::resolve_scene("tri", dir);
    EXPECT_EQ(spec.path, dir + "/tri.obj");
    ASSERT_EQ(spec.views.size(), 1u);
    EXPECT_EQ(spec.views[0].eye.z, 3.0f);
    EXPECT_EQ(spec.views[0].vfov_degrees, 50.0f);
    EXPECT_TRUE(spec.has_light);
    EXPECT_EQ(spec.light.z, 3.0f);
    EXPECT_EQ(spec.ao_radius, 0.25f);
    const bench::LoadedScene loaded = bench::load_bench_scene(spec);
    const bench::ViewSetup view = bench::make_view_setup(loaded, 0, 32, 16);
    EXPECT_EQ(view.width, 32);
    EXPECT_EQ(view.ao_radius, 0.25f);
    EXPECT_THROW(bench::make_view_setup(loaded, 1, 32, 16), Error);
    EXPECT_THROW(bench::resolve_scene("bad", dir), Error);
    EXPECT_THROW(bench::resolve_scene("nofile", dir), Error);
    EXPECT_THROW(bench::resolve_scene("unknown", dir), Error);
    EXPECT_THROW(bench::resolve_scene("unknown", ""), Error);
    EXPECT_EQ(bench::resolve_scene("builtin:cube", dir).path, "builtin:cube");
}

TEST(BenchScenes, SharedViewsJsonNamesLoad) {
    const std::string views = test::shared_path("scenes/views.json");
    if (views.empty()) GTEST_SKIP() << "../shared/scenes is absent";
    const std::string dir = views.substr(0, views.size() - std::strlen("/views.json"));
    const bench::SceneSpec spec = bench::resolve_scene("bunny", dir);
    EXPECT_EQ(spec.views.size(), 1u);
    EXPECT_TRUE(spec.has_light);
    EXPECT_GT(spec.ao_radius, 0.0f);
}

TEST(BenchScenes, CopiesOfAViewsJsonSceneFormAGrid) {
    const std::string dir = test::temp_dir("bench_copies");
    {
        std::ofstream out(dir + "/views.json");
        out << R"({"scenes": {"tri": {"file": "tri.obj", "views": [{"eye": [0, 0, 3], "target": [0, 0, 0]}],
                                      "light": [1, 2, 3], "ao_radius": 0.25}}})";
    }
    {
        std::ofstream out(dir + "/tri.obj");
        out << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    }
    const bench::SceneSpec spec = bench::resolve_scene("tri-x5", dir);
    EXPECT_EQ(spec.name, "tri-x5");
    EXPECT_EQ(spec.copies, 5);
    EXPECT_TRUE(spec.views.empty());  // framed from +z, not the single model's view
    EXPECT_FALSE(spec.has_light);
    EXPECT_EQ(spec.ao_radius, 0.25f);
    const bench::LoadedScene loaded = bench::load_bench_scene(spec);
    ASSERT_EQ(loaded.geometry.triangles.size(), 5u);
    // 3 columns of unit cells fill a 4:3 frame best (2 or 4 would leave more of it empty); 1.05 apart.
    EXPECT_EQ(bench::scene_copy_columns(Box3f(Vec3f(0, 0, 0), Vec3f(1, 1, 0)), 5), 3);
    EXPECT_EQ(bench::scene_copy_columns(Box3f(Vec3f(0, 0, 0), Vec3f(4, 1, 0)), 6), 1);  // wide models stack
    for (size_t i = 0; i < 5; ++i) {
        const Vec3f offset = bench::scene_copy_offset(Box3f(Vec3f(0, 0, 0), Vec3f(1, 1, 0)), int(i), 5);
        EXPECT_EQ(loaded.geometry.triangles[i].v0, offset) << i;
        EXPECT_FLOAT_EQ(offset.x, 1.05f * float(i % 3));
        EXPECT_FLOAT_EQ(offset.y, -1.05f * float(i / 3));
    }
    // The camera frames the grid: at 4:3 a third of the rays hit (5 half-square triangles in a 3x2 grid).
    bench::ViewSetup view = bench::make_view_setup(loaded, 0, 64, 48);
    EXPECT_EQ(view.camera.target, loaded.geometry.bounds.center());
    const auto accel = build_accel(loaded.geometry);
    const bench::RaySet primary = bench::make_primary_rays(view);
    std::vector<Hit> hits(primary.rays.size());
    accel->intersect(primary.rays, hits);
    size_t found = 0;
    for (const Hit& h : hits) found += h.found() ? 1 : 0;
    EXPECT_GT(double(found), 0.25 * double(hits.size()));
    EXPECT_THROW(bench::resolve_scene("tri-x1", dir), Error);
    EXPECT_THROW(bench::resolve_scene("tri-x65", dir), Error);
    EXPECT_THROW(bench::resolve_scene("nothing-x3", dir), Error);
}

TEST(BenchScenes, GeneratedScenesLoadByName) {
    const bench::SceneSpec spec = bench::resolve_scene("generate:terrain-statues@5K#7", "");
    EXPECT_EQ(spec.name, "generate:terrain-statues@5K#7");
    EXPECT_TRUE(spec.statue_dir.empty());
    const bench::LoadedScene loaded = bench::load_bench_scene(spec);
    EXPECT_NEAR(double(loaded.geometry.triangles.size()), 5000.0, 0.05 * 5000.0);
    // Deterministic from the seed, and the seed matters.
    const bench::LoadedScene again = bench::load_bench_scene(spec);
    ASSERT_EQ(again.geometry.triangles.size(), loaded.geometry.triangles.size());
    EXPECT_EQ(std::memcmp(again.geometry.triangles.data(), loaded.geometry.triangles.data(),
                          loaded.geometry.triangles.size() * sizeof(Triangle)),
              0);
    const bench::LoadedScene other = bench::load_bench_scene(bench::resolve_scene("generate:terrain-statues@5K#8", ""));
    EXPECT_FALSE(other.geometry.triangles.size() == loaded.geometry.triangles.size() &&
                 std::memcmp(other.geometry.triangles.data(), loaded.geometry.triangles.data(),
                             loaded.geometry.triangles.size() * sizeof(Triangle)) == 0);
    for (const char* bad : {"generate:terrain-statues", "generate:nope@1M", "generate:terrain@", "generate:terrain@12Q",
                            "generate:terrain@1M#x", "generate:terrain#3@1M"})
        EXPECT_THROW(bench::resolve_scene(bad, ""), Error) << bad;
}

TEST(BenchScenes, FifteenDragonsResolveFromSharedScenes) {
    const std::string views = test::shared_path("scenes/views.json");
    if (views.empty()) GTEST_SKIP() << "../shared/scenes is absent: dragon-x15 cannot be checked";
    const std::string dir = views.substr(0, views.size() - std::strlen("/views.json"));
    const bench::SceneSpec fifteen = bench::resolve_scene("dragon-x15", dir);
    EXPECT_EQ(fifteen.copies, 15);
    EXPECT_EQ(fifteen.path, bench::resolve_scene("dragon", dir).path);
    // Loading 15 copies (13.1M triangles) is the device script's job; two show the replication.
    const bench::LoadedScene two = bench::load_bench_scene(bench::resolve_scene("dragon-x2", dir));
    EXPECT_EQ(two.geometry.triangles.size(), 2u * 871414u);
    // The generated scene takes the Stanford statues from there.
    EXPECT_EQ(bench::resolve_scene("generate:terrain-statues@12M", dir).statue_dir, dir);
}

TEST(BenchRunner, RecordsEveryRaySetAndAgreesWithThePeer) {
    bench::BenchConfig config;
    config.scenes = {"builtin:cornell"};
    config.resolutions = {{32, 24}};
    config.candidates = bench::select_candidates({"bvh"}, {"binned"}, {"bvh2"}, nullptr);
    if (bench::embree_available()) config.embree = {bench::EmbreeQuality::Medium};
    config.repetitions = 2;
    config.build_repetitions = 1;
    config.threads = 2;
    config.progress = false;
    std::ostringstream log;
    size_t scenes_reported = 0;
    const auto records =
        bench::run_bench(config, log, [&](const std::vector<bench::BenchRecord>&) { ++scenes_reported; });
    EXPECT_EQ(scenes_reported, 1u);
    ASSERT_EQ(records.size(), 5u);
    for (const auto& r : records) {
        EXPECT_GT(r.rays, 0u);
        EXPECT_GT(r.mrays_per_s, 0.0);
        EXPECT_EQ(r.trace_ms_runs.size(), 2u);
        EXPECT_TRUE(r.has_counts);
        EXPECT_GT(r.steps_per_ray, 0.0);
        EXPECT_GT(r.stats.sah_cost, 1.0);
        if (bench::embree_available()) {
            ASSERT_EQ(r.embree.size(), 1u);
            EXPECT_GE(r.embree[0].agreement, 0.99) << bench::ray_set_name(r.ray_set);
        }
    }
}

std::vector<std::string> labels_of(const std::vector<bench::GpuCandidate>& rows) {
    std::vector<std::string> labels;
    for (const auto& row : rows) labels.push_back(row.label());
    return labels;
}

TEST(BenchGpuCandidates, PresetStructuresMapToTheirKernels) {
    const bench::Preset& zlatuska = bench::find_preset("zlatuska2009");
    const auto rows002 = bench::gpu_candidates(zlatuska.gpu_kernels, bench::candidates_by_label(zlatuska.candidates, nullptr));
    EXPECT_EQ(labels_of(rows002),
              (std::vector<std::string>{"grid/uniform-auto/grid", "kdtree/sah/kd-short-stack", "kdtree/sah/kd-restart",
                                        "bvh/binned/aila-laine", "bvh/binned/cwbvh"}));
    const bench::Preset& bogolepov = bench::find_preset("bogolepov");
    const auto rows001 = bench::gpu_candidates(bogolepov.gpu_kernels, bench::candidates_by_label(bogolepov.candidates, nullptr));
    EXPECT_EQ(labels_of(rows001),
              (std::vector<std::string>{"grid/uniform-32/grid", "grid/uniform-64/grid", "grid/uniform-128/grid",
                                        "grid-proximity/uniform-32/grid-proximity",
                                        "grid-proximity/uniform-64/grid-proximity",
                                        "grid-proximity/uniform-128/grid-proximity", "bvh/binned/aila-laine",
                                        "bvh/binned/cwbvh"}));
    // The grids keep the preset's resolutions and structures.
    EXPECT_EQ(rows001[1].build.options.grid.resolution, 64);
    EXPECT_EQ(rows001[1].kernel, GpuKernel::Grid);
    EXPECT_EQ(rows001[4].build.options.structure, Structure::ProximityGrid);
    EXPECT_EQ(rows001[4].kernel, GpuKernel::ProximityGrid);
    const bench::Preset& garanzha = bench::find_preset("garanzha2014");
    const auto rows000 = bench::gpu_candidates(garanzha.gpu_kernels, bench::candidates_by_label(garanzha.candidates, nullptr));
    // Every builder (one candidate each), each traced by aila-laine and cwbvh.
    EXPECT_EQ(garanzha.gpu_kernels, (std::vector<GpuKernel>{GpuKernel::AilaLaine, GpuKernel::Cwbvh}));
    EXPECT_EQ(rows000.size(), 2u * garanzha.candidates.size());
}

TEST(BenchGpuCandidates, EveryKernelGetsABuildAndBuildersMultiplyRows) {
    const auto bvh = bench::select_candidates({"bvh"}, {"binned", "sbvh"}, {"all"}, nullptr);
    const auto rows = bench::gpu_candidates(all_gpu_kernels(), bvh);
    // Five BVH kernels (two of them FMA variants) x two builders, then the default kd-tree and grids.
    EXPECT_EQ(labels_of(rows),
              (std::vector<std::string>{"bvh/binned/bvh2", "bvh/sbvh/bvh2", "bvh/binned/aila-laine",
                                        "bvh/sbvh/aila-laine", "bvh/binned/aila-laine-fma", "bvh/sbvh/aila-laine-fma",
                                        "bvh/binned/cwbvh", "bvh/sbvh/cwbvh", "bvh/binned/cwbvh-fma",
                                        "bvh/sbvh/cwbvh-fma", "kdtree/sah/kd-short-stack", "kdtree/sah/kd-restart",
                                        "grid/uniform-auto/grid", "grid-proximity/uniform-auto/grid-proximity"}));
    EXPECT_EQ(rows[1].build.options.builder, Builder::Sbvh);
    for (GpuKernel kernel : all_gpu_kernels())
        EXPECT_NE(bench::gpu_kernel_structure(kernel), "?") << to_string(kernel);
}

TEST(BenchGpu, RowsWithoutTheBackendFailWithOneReason) {
    if (cuda_backend_built()) GTEST_SKIP() << "the CUDA backend is built";
    bench::BenchConfig config;
    config.scenes = {"builtin:cube"};
    config.resolutions = {{8, 8}};
    config.candidates = bench::select_candidates({"bvh"}, {"binned"}, {"bvh2"}, nullptr);
    config.gpu = bench::gpu_candidates({GpuKernel::Cwbvh}, config.candidates);
    config.progress = false;
    std::ostringstream log;
    try {
        bench::run_bench(config, log);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("built without the CUDA backend"), std::string::npos) << e.what();
    }
    EXPECT_EQ(bench::gpu_device_name(0), "");
    // Every CUDA request through the library gets the same reason.
    const Scene scene = make_builtin_scene("cube");
    const SceneGeometry geometry = SceneGeometry::build(scene);
    BuildOptions lbvh;
    lbvh.builder = Builder::Lbvh30;
    lbvh.device = parse_device("cuda");
    EXPECT_THROW((void)build_accel(geometry, lbvh), Error);
    EXPECT_THROW((void)build_bvh(geometry.triangles, lbvh), Error);
    BuildOptions grid;
    grid.structure = Structure::ProximityGrid;
    grid.gpu_kernel = GpuKernel::ProximityGrid;
    grid.device = parse_device("cuda:1");
    EXPECT_THROW((void)build_accel(geometry, grid), Error);
    EXPECT_THROW(require_device(parse_device("cuda")), Error);
    EXPECT_NE(list_cuda_devices().error.find("built without the CUDA backend"), std::string::npos);
    EXPECT_TRUE(list_cuda_devices().devices.empty());
}

TEST(BenchGpu, DeviceBuildLineListsTheStagesThatRan) {
    bench::DeviceBuildSummary b;
    b.report.on_device = true;
    b.report.device_stages = {{"bounds", 0.5}, {"sort", 1.5}, {"clusters", 0.25}, {"bottom", 2.0}, {"boxes", 0.75}};
    b.report.device_ms = 5.0;
    b.report.host_ms = 7.0;
    b.report.peak_device_bytes = 3u << 20;
    b.report.detail = "7 clusters, 9 bottom levels";
    b.nodes = 123;
    b.sah_cost = 45.5;
    const std::string line = bench::format_device_build(b);
    for (const char* part : {"device build 5.000 ms", "bounds 0.500", "boxes 0.750", "peak 3.00 MiB", "123 nodes",
                             "SAH 45.50", "7 clusters", "host 7.00 ms"})
        EXPECT_NE(line.find(part), std::string::npos) << part << " in " << line;
    EXPECT_EQ(line.find("first ray"), std::string::npos);  // no tracer placed it
    b.report.first_ray_ms = 12.5;
    EXPECT_NE(bench::format_device_build(b).find("first ray after 12.500 ms"), std::string::npos);
    // Grids have no SAH; host builds say so.
    b.sah_cost = std::nan("");
    EXPECT_EQ(bench::format_device_build(b).find("SAH"), std::string::npos);
    b.report.on_device = false;
    EXPECT_EQ(bench::format_device_build(b), "built on the host");
    b.report.layout_ms = 0.25;
    EXPECT_EQ(bench::format_device_build(b), "built on the host, layout converted on the device in 0.250 ms");
}

// GPU rows as the runner makes them, printed and written next to a CPU row.
TEST(BenchReport, GpuRowsNameTheirDeviceSamplesAndAgreement) {
    bench::BenchRecord cpu;
    cpu.scene = "builtin:cube";
    cpu.triangles = 12;
    cpu.width = 32;
    cpu.height = 24;
    cpu.candidate = bench::select_candidates({"bvh"}, {"binned"}, {"bvh2"}, nullptr).front();
    cpu.rays = 768;
    cpu.mrays_per_s = 10.0;
    cpu.trace_ms = 0.0768;
    bench::BenchRecord gpu = cpu;
    gpu.device = "cuda:0";
    gpu.gpu = "Test GPU";
    gpu.candidate = bench::gpu_candidates({GpuKernel::Cwbvh}, {cpu.candidate}).front().build;
    gpu.samples_per_pixel = 4;
    gpu.rays = 4 * 768;
    gpu.mrays_per_s = 1000.0;
    gpu.device_bytes = 3u << 20;
    gpu.reference = bench::ReferenceAgreement{cpu.candidate.label(), 0.995, 1e-6};
    std::ostringstream table;
    bench::print_scene_tables(table, {cpu, gpu}, 2, 5, 3);
    const std::string text = table.str();
    EXPECT_NE(text.find("cpu 1 (centre)"), std::string::npos) << text;
    EXPECT_NE(text.find("cuda:0 4 (jittered) on Test GPU"), std::string::npos) << text;
    EXPECT_NE(text.find("cuda:0 bvh/binned/cwbvh"), std::string::npos) << text;
    EXPECT_NE(text.find("99.5000%"), std::string::npos) << text;
    EXPECT_NE(text.find("3,072"), std::string::npos) << text;

    const std::string path = test::temp_dir("bench_report_gpu") + "/out.json";
    EXPECT_EQ(text.find("kernel resources"), std::string::npos) << text;  // none listed
    GpuKernelResources closest;
    closest.kernel = "cwbvh closest (grid-stride)";
    closest.registers = 64;
    closest.local_bytes = 512;
    closest.block_size = 128;
    closest.blocks_per_sm = 8;
    closest.occupancy = 0.5;
    gpu.kernel_resources = {closest};
    std::ostringstream with_resources;
    bench::print_scene_tables(with_resources, {cpu, gpu, gpu}, 2, 5, 3);
    const std::string resources = with_resources.str();
    const size_t line = resources.find("cwbvh closest (grid-stride)");
    ASSERT_NE(line, std::string::npos) << resources;
    EXPECT_EQ(resources.find("cwbvh closest (grid-stride)", line + 1), std::string::npos) << "printed once";
    EXPECT_NE(resources.find("64 regs    512 B local"), std::string::npos) << resources;
    EXPECT_NE(resources.find("occupancy  50.0%"), std::string::npos) << resources;

    bench::RunInfo info;
    info.devices = {"cpu", "cuda:0"};
    info.gpu = "Test GPU";
    bench::write_json(path, {cpu, gpu}, info);
    std::ifstream in(path);
    const nlohmann::json root = nlohmann::json::parse(in);
    EXPECT_EQ(root["machine"]["gpu"], "Test GPU");
    ASSERT_EQ(root["records"].size(), 2u);
    const auto& cpu_json = root["records"][0];
    const auto& gpu_json = root["records"][1];
    EXPECT_EQ(cpu_json["device"], "cpu");
    EXPECT_TRUE(cpu_json["gpu"].is_null());
    EXPECT_EQ(cpu_json["samples_per_pixel"], 1);
    EXPECT_EQ(gpu_json["device"], "cuda:0");
    EXPECT_EQ(gpu_json["gpu"], "Test GPU");
    EXPECT_EQ(gpu_json["gpu_kernel"], "cwbvh");
    EXPECT_EQ(gpu_json["samples_per_pixel"], 4);
    EXPECT_DOUBLE_EQ(gpu_json["reference"]["agreement"].get<double>(), 0.995);
    EXPECT_TRUE(cpu_json["kernel_resources"].is_null());
    ASSERT_EQ(gpu_json["kernel_resources"].size(), 1u);
    EXPECT_EQ(gpu_json["kernel_resources"][0]["kernel"], "cwbvh closest (grid-stride)");
    EXPECT_EQ(gpu_json["kernel_resources"][0]["registers"], 64);
    EXPECT_EQ(gpu_json["kernel_resources"][0]["local_bytes"], 512);
    EXPECT_DOUBLE_EQ(gpu_json["kernel_resources"][0]["occupancy"].get<double>(), 0.5);
}

TEST(BenchGpu, KernelResourcesNeedACudaDevice) {
    EXPECT_THROW(gpu_kernel_resources(GpuKernel::AilaLaine, Device{}), Error);
    if (cuda_backend_built()) GTEST_SKIP() << "built with the CUDA backend: tests/gpu checks the figures";
    try {
        gpu_kernel_resources(GpuKernel::AilaLaine, Device{Device::Kind::Cuda, 0});
        FAIL() << "no error without the backend";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("without the CUDA backend"), std::string::npos) << e.what();
    }
}

TEST(BenchRender, TraceShareOfAPassAndItsJson) {
    bench::RenderBenchConfig config;
    config.integrators = {"path"};
    config.width = 32;
    config.height = 24;
    config.max_depth = 2;
    config.repetitions = 1;
    config.threads = 2;
    const bench::LoadedScene scene = bench::load_bench_scene(bench::resolve_scene("builtin:cornell", ""));
    std::ostringstream progress;
    const std::vector<bench::RenderBenchRecord> records = bench::run_render_bench(scene, config, progress);
    ASSERT_EQ(records.size(), 1u);
    const bench::RenderBenchRecord& r = records.front();
    ASSERT_GT(r.pass_ms, 0.0);
    EXPECT_DOUBLE_EQ(r.trace_share, r.trace_ms / r.pass_ms);
    EXPECT_DOUBLE_EQ(r.shading_fraction, 1.0 - r.trace_share);
    std::ostringstream table;
    bench::print_render_table(table, records);
    EXPECT_NE(table.str().find("trace share"), std::string::npos) << table.str();

    bench::RenderBenchRecord device = r;  // a device row whose integrator has no trace launches
    device.device = "cuda:0";
    device.gpu = "Test GPU";
    device.trace_ms = device.batch_trace_ms = device.trace_share = device.shading_fraction = std::nan("");
    const std::string path = test::temp_dir("bench_render_json") + "/render.json";
    bench::write_render_json(path, {r, device}, "rayforge bench --integrator path");
    std::ifstream in(path);
    const nlohmann::json root = nlohmann::json::parse(in);
    EXPECT_EQ(root["machine"]["gpu"], "Test GPU");
    EXPECT_EQ(root["command"], "rayforge bench --integrator path");
    ASSERT_EQ(root["records"].size(), 2u);
    EXPECT_DOUBLE_EQ(root["records"][0]["trace_share"].get<double>(), r.trace_share);
    EXPECT_TRUE(root["records"][1]["trace_share"].is_null());
    EXPECT_EQ(root["records"][1]["device"], "cuda:0");
}

}  // namespace
}  // namespace rf
