// Watertight ray/triangle test: hits, misses, t range, barycentrics,
// degenerate triangles, and no ray slipping between triangles of closed meshes.
#include "trace/triangle_intersect.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "accel/brute_force.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"

namespace rf {
namespace {

const Triangle kUnitTriangle{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};

bool hit_triangle(const Ray& ray, const Triangle& tri, TriangleHit& hit) {
    return intersect_triangle(WatertightRay::make(ray), tri, ray.tmin, ray.tmax, hit);
}

TEST(TriangleIntersect, HitsWithDistanceAndBarycentrics) {
    TriangleHit hit{};
    ASSERT_TRUE(hit_triangle(Ray{Vec3f(0.25f, 0.5f, 2.0f), 0.0f, Vec3f(0, 0, -1)}, kUnitTriangle, hit));
    EXPECT_FLOAT_EQ(hit.t, 2.0f);
    EXPECT_FLOAT_EQ(hit.u, 0.25f);  // weight of v1 = (1, 0, 0)
    EXPECT_FLOAT_EQ(hit.v, 0.5f);   // weight of v2 = (0, 1, 0)
}

TEST(TriangleIntersect, BothFacingsHit) {
    TriangleHit front{}, back{};
    EXPECT_TRUE(hit_triangle(Ray{Vec3f(0.2f, 0.2f, 1.0f), 0.0f, Vec3f(0, 0, -1)}, kUnitTriangle, front));
    EXPECT_TRUE(hit_triangle(Ray{Vec3f(0.2f, 0.2f, -1.0f), 0.0f, Vec3f(0, 0, 1)}, kUnitTriangle, back));
    EXPECT_FLOAT_EQ(front.t, 1.0f);
    EXPECT_FLOAT_EQ(back.t, 1.0f);
    EXPECT_FLOAT_EQ(front.u, back.u);
    EXPECT_FLOAT_EQ(front.v, back.v);
}

TEST(TriangleIntersect, MissesOutsideBehindAndParallel) {
    TriangleHit hit{};
    EXPECT_FALSE(hit_triangle(Ray{Vec3f(0.6f, 0.6f, 1.0f), 0.0f, Vec3f(0, 0, -1)}, kUnitTriangle, hit));
    EXPECT_FALSE(hit_triangle(Ray{Vec3f(-0.1f, 0.5f, 1.0f), 0.0f, Vec3f(0, 0, -1)}, kUnitTriangle, hit));
    EXPECT_FALSE(hit_triangle(Ray{Vec3f(0.2f, 0.2f, 1.0f), 0.0f, Vec3f(0, 0, 1)}, kUnitTriangle, hit));  // behind
    // In the triangle's plane.
    EXPECT_FALSE(hit_triangle(Ray{Vec3f(-1.0f, 0.2f, 0.0f), 0.0f, Vec3f(1, 0, 0)}, kUnitTriangle, hit));
    // A zero direction never hits.
    EXPECT_FALSE(hit_triangle(Ray{Vec3f(0.2f, 0.2f, 0.0f), 0.0f, Vec3f(0, 0, 0)}, kUnitTriangle, hit));
}

TEST(TriangleIntersect, RespectsClosedDistanceInterval) {
    TriangleHit hit{};
    const Vec3f org(0.2f, 0.2f, 3.0f), dir(0, 0, -1);
    ASSERT_TRUE(hit_triangle(Ray{org, 0.0f, dir, kInfinity}, kUnitTriangle, hit));
    const float t = hit.t;
    EXPECT_NEAR(t, 3.0f, 1e-6f);
    EXPECT_TRUE(hit_triangle(Ray{org, t, dir, t}, kUnitTriangle, hit));  // closed: tmin == tmax == t
    EXPECT_FALSE(hit_triangle(Ray{org, std::nextafter(t, 10.0f), dir, kInfinity}, kUnitTriangle, hit));
    EXPECT_FALSE(hit_triangle(Ray{org, 0.0f, dir, std::nextafter(t, 0.0f)}, kUnitTriangle, hit));
    EXPECT_FALSE(hit_triangle(Ray{org, 3.5f, dir, kInfinity}, kUnitTriangle, hit));
    EXPECT_FALSE(hit_triangle(Ray{org, 0.0f, dir, 2.5f}, kUnitTriangle, hit));
    EXPECT_TRUE(hit_triangle(Ray{org, 2.5f, dir, 3.5f}, kUnitTriangle, hit));
    // Unnormalised directions measure t in units of dir.
    ASSERT_TRUE(hit_triangle(Ray{org, 0.0f, Vec3f(0, 0, -4), kInfinity}, kUnitTriangle, hit));
    EXPECT_FLOAT_EQ(hit.t, 0.75f);
}

TEST(TriangleIntersect, BarycentricsReproduceTheHitPoint) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> coord(-10.0f, 10.0f), unit(0.0f, 1.0f);
    int hits = 0;
    for (int i = 0; i < 2000; ++i) {
        const Triangle tri{Vec3f(coord(rng), coord(rng), coord(rng)), Vec3f(coord(rng), coord(rng), coord(rng)),
                           Vec3f(coord(rng), coord(rng), coord(rng))};
        if (tri.area() < 1.0f) continue;
        float b1 = unit(rng), b2 = unit(rng);
        if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
        const Vec3f target = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
        const Vec3f org(coord(rng), coord(rng), coord(rng));
        TriangleHit hit{};
        if (!hit_triangle(Ray{org, 0.0f, target - org, kInfinity}, tri, hit)) {
            // Only points extremely close to an edge may be missed by rounding.
            EXPECT_LT(std::min({b1, b2, 1.0f - b1 - b2}), 1e-4f);
            continue;
        }
        ++hits;
        EXPECT_NEAR(hit.t, 1.0f, 1e-4f);
        EXPECT_NEAR(hit.u, b1, 1e-3f);
        EXPECT_NEAR(hit.v, b2, 1e-3f);
        const Vec3f p = tri.v0 * (1.0f - hit.u - hit.v) + tri.v1 * hit.u + tri.v2 * hit.v;
        EXPECT_LT(length(p - target), 1e-3f);
    }
    EXPECT_GT(hits, 1000);
}

TEST(TriangleIntersect, DegenerateTrianglesNeverHit) {
    const Vec3f a(1.0f, 2.0f, 3.0f), b(2.0f, -1.0f, 0.5f);
    const Triangle degenerate[] = {
        {a, a, a},                    // a point
        {a, b, a},                    // repeated vertex
        {a, b, (a + b) * 0.5f},       // collinear
        {a, b, a + (b - a) * 2.0f},   // collinear, beyond
        {b, a, a + (a - b) * 0.25f},  // collinear, other order
    };
    std::mt19937 rng(3);
    const Box3f around{Vec3f(-5.0f), Vec3f(5.0f)};
    for (const Triangle& tri : degenerate) {
        for (int i = 0; i < 500; ++i) {
            const Vec3f org = test::random_in_box(rng, around);
            // Aim exactly at the vertices, their midpoint, and random directions.
            for (Vec3f target : {tri.v0, tri.v1, tri.v2, (tri.v0 + tri.v1) * 0.5f}) {
                TriangleHit hit{};
                EXPECT_FALSE(hit_triangle(Ray{org, 0.0f, target - org, kInfinity}, tri, hit));
            }
            TriangleHit hit{};
            EXPECT_FALSE(hit_triangle(Ray{org, 0.0f, test::random_direction(rng), kInfinity}, tri, hit));
        }
    }
}

// Targets on a closed mesh where rays most easily slip through cracks: every
// vertex, and points on every edge (midpoints and random points, in float).
std::vector<Vec3f> vertex_and_edge_targets(const test::IndexedMesh& mesh, std::mt19937& rng) {
    std::vector<Vec3f> targets = mesh.positions;
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (size_t i = 0; i < mesh.indices.size(); i += 3) {
        for (int e = 0; e < 3; ++e) {
            const Vec3f a = mesh.positions[mesh.indices[i + e]];
            const Vec3f b = mesh.positions[mesh.indices[i + (e + 1) % 3]];
            targets.push_back((a + b) * 0.5f);
            targets.push_back(lerp(a, b, unit(rng)));
        }
    }
    return targets;
}

// Every ray from inside a closed mesh, and every ray from outside aimed at
// its surface towards the centre, must hit it.
void expect_watertight(const test::IndexedMesh& mesh, uint32_t seed) {
    const SceneGeometry geometry = test::to_geometry(mesh);
    const BruteForceAccel brute(geometry);
    const auto bvh = build_accel(geometry, BuildOptions{.max_leaf_size = 2});
    std::mt19937 rng(seed);
    const std::vector<Vec3f> targets = vertex_and_edge_targets(mesh, rng);
    std::uniform_real_distribution<float> jitter(-0.05f, 0.05f), distance(0.5f, 20.0f);
    int rays = 0, misses = 0;
    for (const Vec3f& target : targets) {
        // From the centre outwards: the direction is the target itself, exactly.
        const Ray from_centre{Vec3f(0.0f), 0.0f, target, kInfinity};
        // From a random point outside towards the target (and on to the centre).
        const Vec3f away = target * distance(rng) + Vec3f(jitter(rng), jitter(rng), jitter(rng));
        const Ray from_outside{target + away, 0.0f, target - (target + away), kInfinity};
        for (const Ray& ray : {from_centre, from_outside}) {
            ++rays;
            const bool brute_hit = brute.intersect(ray).found();
            const bool bvh_hit = bvh->intersect(ray).found();
            misses += !brute_hit;
            EXPECT_TRUE(brute_hit) << "ray from (" << ray.org.x << ", " << ray.org.y << ", " << ray.org.z
                                   << ") towards (" << target.x << ", " << target.y << ", " << target.z << ")";
            EXPECT_TRUE(bvh_hit);
            EXPECT_TRUE(bvh->occluded(ray));
        }
    }
    EXPECT_GT(rays, 5000);
    EXPECT_EQ(misses, 0);
}

TEST(TriangleIntersect, IcosphereIsWatertightAtVerticesAndEdges) {
    expect_watertight(test::make_icosphere(3), 11);
}

TEST(TriangleIntersect, TessellatedCubeIsWatertightAtVerticesAndEdges) {
    expect_watertight(test::make_tessellated_cube(12), 12);
}

}  // namespace
}  // namespace rf
