// Rays whose [tmin, tmax] reaches behind the origin (tmin < 0, also tmax < 0)
// against every CPU traversal: the robust slab test's far widening
// (detail::widen_far, Ize 2013's 1 + 2 gamma(3)) must widen a negative far
// distance too. Multiplying it by 1 + 2 gamma(3) moves it towards -inf and
// culls boxes (flat, axis-aligned ones first) that the ray crosses behind its
// origin. Closest hit and any hit of each structure, layout and traversal are
// compared with brute force.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel/update/bvh_updater.h"
#include "accel_test_scenes.h"
#include "candidates.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"
#include "trace/aila_laine_fma_traversal.h"
#include "trace/aila_laine_traversal.h"
#include "trace/bvh_traversal.h"
#include "trace/cwbvh_fma_traversal.h"
#include "trace/cwbvh_traversal.h"

namespace rf {
namespace {

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

// Axis-aligned faces give flat boxes, where the near and far distances are
// equal and any narrowing of the far one culls the box.
std::vector<NamedScene> behind_scenes() {
    return {{"cube", test::to_geometry(test::make_tessellated_cube(6))},
            {"nasty", test::make_nasty_geometry(9)},
            {"soup", test::make_triangle_soup(600, 21, {Vec3f(-4.0f), Vec3f(4.0f)}, 0.8f)}};
}

// Rays pointing away from a triangle (it lies behind the origin, at t < 0),
// some axis-parallel; intervals [tmin, inf], [tmin, tmax > 0] and
// [tmin, tmax < 0] (entirely behind the origin).
std::vector<Ray> behind_rays(const SceneGeometry& g, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<size_t> pick(0, g.triangles.size() - 1);
    const float size = length(g.bounds.extent());
    const Box3f around{g.bounds.lo - Vec3f(0.2f * size), g.bounds.hi + Vec3f(0.2f * size)};
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        const Triangle& tri = g.triangles[pick(rng)];
        float b1 = unit(rng), b2 = unit(rng);
        if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
        const Vec3f target = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
        Ray ray;
        if (i % 3 == 0) {
            Vec3f d(0.0f);
            d[int(i / 3 % 3)] = (i & 4) ? 1.0f : -1.0f;
            ray.org = target + d * (size * (0.05f + unit(rng)));
            ray.dir = d;
        } else {
            ray.org = test::random_in_box(rng, around);
            ray.dir = ray.org - target;
            if (length_squared(ray.dir) == 0.0f) ray.dir = Vec3f(0.0f, 0.0f, 1.0f);
        }
        const float reach = 2.0f * size / length(ray.dir);  // in units of t: past the whole scene
        ray.tmin = -reach * (0.5f + unit(rng));
        switch (i % 4) {
            case 0: break;  // tmax = inf
            case 1: ray.tmax = reach * unit(rng); break;
            case 2: ray.tmax = ray.tmin * unit(rng) * 0.5f; break;  // all behind the origin
            case 3: ray.tmax = -0.0f; break;
        }
        rays.push_back(ray);
    }
    return rays;
}

// Counts disagreements with brute force (found, and t within 1e-5).
struct Mismatches {
    float relative = 1e-5f;  // t tolerance (two-level: looser, its rays are transformed into mesh space)
    int count = 0;
    std::string first;
    void check(bool ok, const std::string& what) {
        if (!ok && count++ == 0) first = what;
    }
    void check_hit(const Hit& got, const Hit& want, const std::string& what) {
        const bool ok = got.found() == want.found() &&
                        (!want.found() || std::fabs(got.t - want.t) <= relative * std::fmax(std::fabs(want.t), 1e-3f));
        check(ok, what + ": t " + std::to_string(got.t) + " (found " + std::to_string(got.found()) + ") vs " +
                      std::to_string(want.t) + " (found " + std::to_string(want.found()) + ")");
    }
};

TEST(SlabFarScale, WidenFarWidensBothSigns) {
    // Negative t: widened (towards +inf) by at least 2 gamma(3) of |t|.
    // Positive t: exactly t * kSlabFarScale, as before the fix.
    const double two_gamma3 = 2.0 * (3.0 * 0x1p-24) / (1.0 - 3.0 * 0x1p-24);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> exponent(-120.0f, 120.0f);
    for (int i = 0; i < 100000; ++i) {
        const float t = std::exp2(exponent(rng)) * ((i & 1) ? -1.0f : 1.0f);
        const float w = detail::widen_far(t);
        if (t > 0.0f) EXPECT_EQ(w, t * detail::kSlabFarScale) << t;
        else EXPECT_GE(double(w), double(t) + std::fabs(double(t)) * two_gamma3) << t;
    }
    const float inf = std::numeric_limits<float>::infinity();
    EXPECT_EQ(detail::widen_far(0.0f), 0.0f);
    EXPECT_EQ(detail::widen_far(inf), inf);
    EXPECT_EQ(detail::widen_far(-inf), -inf);
}

TEST(SlabFarScale, EveryCatalogueCombinationFindsHitsBehindTheOrigin) {
    for (const NamedScene& scene : behind_scenes()) {
        const BruteForceAccel brute(scene.geometry);
        const std::vector<Ray> rays = behind_rays(scene.geometry, 3000, 17);
        std::vector<Hit> expected(rays.size());
        brute.intersect(rays, expected);
        for (const bench::Candidate& c : bench::candidate_catalogue()) {
            if (!c.implemented || c.options.structure == Structure::BruteForce) continue;
            BuildOptions options = c.options;
            options.threads = 2;
            const auto accel = build_accel(scene.geometry, options);
            std::vector<Hit> batch(rays.size());
            std::vector<uint8_t> blocked(rays.size());
            accel->intersect(rays, batch);
            accel->occluded(rays, blocked);
            Mismatches bad;
            for (size_t i = 0; i < rays.size(); ++i) {
                const std::string what = "ray " + std::to_string(i);
                bad.check_hit(accel->intersect(rays[i]), expected[i], what + " single closest");
                bad.check_hit(batch[i], expected[i], what + " batched closest");
                bad.check(accel->occluded(rays[i]) == expected[i].found(), what + " single any");
                bad.check((blocked[i] != 0) == expected[i].found(), what + " batched any");
            }
            EXPECT_EQ(bad.count, 0) << c.label() << " on " << scene.name << ", first: " << bad.first;
        }
    }
}

TEST(SlabFarScale, BvhCwbvhAndAilaLaineTraversalsFindHitsBehindTheOrigin) {
    for (const NamedScene& scene : behind_scenes()) {
        const BruteForceAccel brute(scene.geometry);
        const std::vector<Ray> rays = behind_rays(scene.geometry, 3000, 23);
        const Bvh bvh = build_bvh(scene.geometry.triangles, BuildOptions{});
        const CwbvhBvh cw = build_cwbvh(bvh, scene.geometry.triangles);
        const AilaLaineBvh al = convert_to_aila_laine(bvh, scene.geometry.triangles);
        const BvhView view{bvh.nodes.data(), bvh.prim_indices.data(), scene.geometry.triangles.data(),
                           uint32_t(bvh.nodes.size())};
        Mismatches bvh2, cwbvh, cwbvh_fma, aila, aila_fma;
        for (size_t i = 0; i < rays.size(); ++i) {
            const Ray& ray = rays[i];
            const Hit want = brute.intersect(ray);
            const std::string what = "ray " + std::to_string(i);
            bvh2.check_hit(bvh_intersect(view, ray), want, what);
            bvh2.check(bvh_occluded(view, ray) == want.found(), what + " any");
            cwbvh.check_hit(cwbvh_intersect(cw.view(), ray), want, what);
            cwbvh.check(cwbvh_occluded(cw.view(), ray) == want.found(), what + " any");
            cwbvh_fma.check_hit(cwbvh_fma_intersect(cw.view(), ray), want, what);
            cwbvh_fma.check(cwbvh_fma_occluded(cw.view(), ray) == want.found(), what + " any");
            aila.check_hit(aila_laine_intersect(al.view(), ray), want, what);
            aila.check(aila_laine_occluded(al.view(), ray) == want.found(), what + " any");
            aila_fma.check_hit(aila_laine_fma_intersect(al.view(), ray), want, what);
            aila_fma.check(aila_laine_fma_occluded(al.view(), ray) == want.found(), what + " any");
        }
        EXPECT_EQ(bvh2.count, 0) << "bvh2 on " << scene.name << ", first: " << bvh2.first;
        EXPECT_EQ(cwbvh.count, 0) << "cwbvh on " << scene.name << ", first: " << cwbvh.first;
        EXPECT_EQ(cwbvh_fma.count, 0) << "cwbvh-fma on " << scene.name << ", first: " << cwbvh_fma.first;
        EXPECT_EQ(aila.count, 0) << "aila-laine on " << scene.name << ", first: " << aila.first;
        EXPECT_EQ(aila_fma.count, 0) << "aila-laine-fma on " << scene.name << ", first: " << aila_fma.first;
    }
}

// The two-level structure (top BVH over instances, one BVH per mesh) on the
// flat-faced cube and a patch, instanced with rotations.
TEST(SlabFarScale, TwoLevelFindsHitsBehindTheOrigin) {
    for (Layout layout : {Layout::Bvh2, Layout::Bvh4, Layout::Bvh8}) {
        Scene scene;
        scene.meshes.push_back(test::to_mesh(test::make_tessellated_cube(4), "cube"));
        std::mt19937 rng(3);
        for (int k = 0; k < 12; ++k) {
            const Vec3f offset = test::random_in_box(rng, Box3f{Vec3f(-6.0f), Vec3f(6.0f)});
            // Rotated: world rays are not in a face's plane, while the
            // bottom-level boxes (in mesh space) stay flat.
            const Affine3f transform =
                Affine3f::translation(offset) * Affine3f::rotation(test::random_direction(rng), 0.3f + 0.2f * float(k));
            scene.instances.push_back({0u, transform});
        }
        scene.finalize();
        const SceneGeometry g = SceneGeometry::build(scene);
        BuildOptions options;
        options.layout = layout;
        auto accel = make_two_level_accel(scene, g, options);
        const BruteForceAccel brute(g);
        const std::vector<Ray> rays = behind_rays(g, 3000, 31);
        std::vector<Hit> batch(rays.size());
        accel->intersect(rays, batch);
        Mismatches bad;
        bad.relative = 1e-3f;  // the ray in mesh space is rounded; a culled box shows as a miss or a farther hit
        size_t ambiguous = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            const Hit want = brute.intersect(rays[i]);
            // In instance space a ray through a mesh edge may hit the other
            // triangle of the edge (as tests/two_level_accel_test.cpp allows).
            const Hit got = accel->intersect(rays[i]);
            auto near_edge = [](const Hit& h) { return h.found() && std::fmin(std::fmin(h.u, h.v), 1.0f - h.u - h.v) < 1e-3f; };
            if (near_edge(want) || near_edge(got)) {
                ++ambiguous;
                continue;
            }
            const std::string what = "ray " + std::to_string(i);
            bad.check_hit(accel->intersect(rays[i]), want, what + " closest");
            bad.check_hit(batch[i], want, what + " batched closest");
            bad.check(accel->occluded(rays[i]) == want.found(), what + " any");
        }
        EXPECT_EQ(bad.count, 0) << to_string(layout) << ", first: " << bad.first;
        EXPECT_LT(ambiguous, rays.size() / 20) << to_string(layout);
    }
}

}  // namespace
}  // namespace rf
