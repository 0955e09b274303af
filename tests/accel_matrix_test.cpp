// Every implemented (structure, builder, layout, traversal) combination of the
// bench catalogue against the brute-force reference: same hit/miss, same
// primitive except exact ties, t within 1e-5 relative, any-hit agreeing with
// closest-hit, batches agreeing with single rays. Scenes cover degenerate,
// duplicate, axis-aligned flat and very thin triangles and coordinates at 1e6.
// A combination joins this test as soon as the catalogue marks it implemented.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel_test_scenes.h"
#include "candidates.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

struct Scene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<Scene> matrix_scenes() {
    std::vector<Scene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(1500, 11, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f)});
    scenes.push_back({"cube", test::to_geometry(test::make_tessellated_cube(8))});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(3), 2.0f, Vec3f(0.5f, 0.0f, 0.0f))});
    scenes.push_back({"nasty", test::make_nasty_geometry(5)});
    scenes.push_back({"far", test::make_triangle_soup(800, 12, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 1.0f)});
    return scenes;
}

// Random rays (some aimed at triangles, some axis-parallel, some with a
// [tmin, tmax] window) plus a coherent pinhole-camera block, so packet paths
// of the batched calls see real packets.
std::vector<Ray> matrix_rays(const SceneGeometry& g, size_t random_count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<size_t> pick(0, g.triangles.size() - 1);
    const Vec3f extent = g.bounds.extent();
    const Vec3f margin = extent * 0.25f + Vec3f(1e-3f);
    const Box3f around{g.bounds.lo - margin, g.bounds.hi + margin};
    std::vector<Ray> rays;
    for (size_t i = 0; i < random_count; ++i) {
        Ray ray;
        ray.org = test::random_in_box(rng, around);
        const Triangle& tri = g.triangles[pick(rng)];
        switch (i % 4) {
            case 0: ray.dir = test::random_direction(rng); break;
            case 1: {
                float b1 = unit(rng), b2 = unit(rng);
                if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
                ray.dir = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2 - ray.org;
                break;
            }
            case 2: {
                Vec3f d(0.0f);
                d[int(i % 3)] = (i & 8) ? 1.0f : -1.0f;
                ray.org = tri.centroid() - d * (length(extent) * 0.3f);
                ray.dir = d;
                break;
            }
            case 3: {
                ray.dir = tri.v2 - ray.org;
                ray.tmin = unit(rng) * 0.5f;
                ray.tmax = 0.5f + unit(rng);
                break;
            }
        }
        if (length_squared(ray.dir) == 0.0f) ray.dir = Vec3f(0.0f, 0.0f, 1.0f);
        rays.push_back(ray);
    }
    // A 32 x 16 camera block looking at the scene centre.
    const Vec3f centre = (g.bounds.lo + g.bounds.hi) * 0.5f;
    const Vec3f eye = centre + Vec3f(0.3f, 0.4f, 1.0f) * (length(extent) * 1.2f + 1.0f);
    const Vec3f forward = normalize(centre - eye);
    const Vec3f right = normalize(cross(forward, Vec3f(0.0f, 1.0f, 0.0f)));
    const Vec3f up = cross(right, forward);
    for (int y = 0; y < 16; ++y) {
        for (int x = 0; x < 32; ++x) {
            Ray ray;
            ray.org = eye;
            ray.dir = normalize(forward + right * ((x - 16) * 0.02f) + up * ((y - 8) * 0.02f));
            rays.push_back(ray);
        }
    }
    return rays;
}

void expect_agrees(const Hit& got, const Hit& expected, const Ray& ray, const std::string& what) {
    ASSERT_EQ(got.found(), expected.found()) << what;
    if (!expected.found()) return;
    const float tolerance = 1e-5f * std::max(std::fabs(expected.t), 1e-30f);
    EXPECT_NEAR(got.t, expected.t, tolerance) << what << ": prim " << got.prim << " vs " << expected.prim;
    if (got.prim == expected.prim) {
        EXPECT_NEAR(got.u, expected.u, 1e-4f) << what;
        EXPECT_NEAR(got.v, expected.v, 1e-4f) << what;
    }
    EXPECT_GE(got.t, ray.tmin) << what;
    EXPECT_LE(got.t, ray.tmax) << what;
}

TEST(AccelMatrix, EveryImplementedCombinationMatchesBruteForce) {
    std::vector<bench::Candidate> combinations;
    for (const bench::Candidate& c : bench::candidate_catalogue())
        if (c.implemented && c.options.structure != Structure::BruteForce) combinations.push_back(c);
    ASSERT_FALSE(combinations.empty());
    for (const Scene& scene : matrix_scenes()) {
        const BruteForceAccel brute(scene.geometry);
        const std::vector<Ray> rays = matrix_rays(scene.geometry, 1500, 77);
        std::vector<Hit> expected(rays.size());
        brute.intersect(rays, expected);
        const size_t hits = size_t(std::count_if(expected.begin(), expected.end(), [](const Hit& h) { return h.found(); }));
        ASSERT_GT(hits, rays.size() / 5) << scene.name;
        ASSERT_LT(hits, rays.size()) << scene.name;
        for (const bench::Candidate& c : combinations) {
            const std::string what = c.label() + " on " + scene.name;
            SCOPED_TRACE(what);
            BuildOptions options = c.options;
            options.threads = 2;
            const auto accel = build_accel(scene.geometry, options);
            std::vector<Hit> batch(rays.size());
            std::vector<uint8_t> blocked(rays.size());
            accel->intersect(rays, batch);
            accel->occluded(rays, blocked);
            int failures = 0;
            for (size_t i = 0; i < rays.size() && failures < 5; ++i) {
                const Hit single = accel->intersect(rays[i]);
                const int before = ::testing::UnitTest::GetInstance()->current_test_info()->result()->total_part_count();
                expect_agrees(single, expected[i], rays[i], what + " ray " + std::to_string(i));
                expect_agrees(batch[i], expected[i], rays[i], what + " batched ray " + std::to_string(i));
                EXPECT_EQ(accel->occluded(rays[i]), expected[i].found()) << what << " ray " << i;
                EXPECT_EQ(blocked[i] != 0, expected[i].found()) << what << " batched ray " << i;
                if (::testing::UnitTest::GetInstance()->current_test_info()->result()->total_part_count() != before)
                    ++failures;
            }
        }
    }
}

TEST(AccelMatrix, EveryImplementedCombinationReportsStats) {
    const SceneGeometry geometry = test::make_triangle_soup(500, 3, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    for (const bench::Candidate& c : bench::candidate_catalogue()) {
        if (!c.implemented) continue;
        SCOPED_TRACE(c.label());
        const auto accel = build_accel(geometry, c.options);
        const AccelStats stats = accel->stats();
        EXPECT_FALSE(stats.name.empty());
        EXPECT_GE(stats.build_ms, 0.0);
        if (c.options.structure != Structure::BruteForce) {
            EXPECT_GT(stats.bytes, 0u);
            EXPECT_GT(stats.node_count, 0u);
        }
        // An empty scene builds and misses.
        const SceneGeometry empty;
        const auto none = build_accel(empty, c.options);
        Ray ray;
        ray.dir = Vec3f(0.0f, 0.0f, 1.0f);
        EXPECT_FALSE(none->intersect(ray).found());
        EXPECT_FALSE(none->occluded(ray));
    }
}

TEST(AccelMatrix, NamesRoundTrip) {
    for (const char* name : {"bvh", "grid", "grid-proximity", "kdtree", "brute"})
        EXPECT_EQ(to_string(parse_structure(name)), name);
    for (const char* name :
         {"binned", "sweep", "sbvh", "lbvh30", "lbvh63", "hlbvh2", "gridbvh", "gridbvh-split", "ploc", "hploc"})
        EXPECT_EQ(to_string(parse_builder(name)), name);
    EXPECT_EQ(parse_builder("lbvh"), Builder::Lbvh30);
    for (const char* name : {"bvh2", "bvh4", "bvh8"}) EXPECT_EQ(to_string(parse_layout(name)), name);
    for (const char* name : {"stack", "short-stack", "restart", "pushdown"})
        EXPECT_EQ(to_string(parse_kd_traversal(name)), name);
    EXPECT_THROW((void)parse_builder("binnned"), Error);
    EXPECT_THROW((void)parse_layout("bvh16"), Error);
}

}  // namespace
}  // namespace rf
