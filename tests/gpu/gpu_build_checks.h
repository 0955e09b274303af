// What the device-builder tests (tests/gpu/*_build_test.cpp) share: the device
// gate (gpu_test_device.h), named test scenes with the degenerate inputs every
// builder must survive, and the bit-exact BVH comparison.
#pragma once

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "../accel_test_scenes.h"
#include "accel/brute_force.h"
#include "gpu_test_device.h"
#include "rayforge/accel/bvh/bvh.h"
#include "trace/bvh_traversal.h"

namespace rf::gpu_build_test {

inline bool same_box(const Box3f& a, const Box3f& b) { return std::memcmp(&a, &b, sizeof(Box3f)) == 0; }

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

// The scenes every device-builder test starts from: a soup, a sphere and
// the nasty geometry (slivers, duplicates, huge and tiny triangles).
inline std::vector<NamedScene> common_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(5))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    return scenes;
}

// Appends every triangle in one point (all Morton codes equal) and two triangles.
inline void append_degenerate_scenes(std::vector<NamedScene>& scenes) {
    SceneGeometry point;
    for (int i = 0; i < 1000; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"one point", std::move(point)});
    SceneGeometry two;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(0, 0, 2), Vec3f(1, 0, 2), Vec3f(0, 1, 2)});
    scenes.push_back({"two", std::move(two)});
}

// Same nodes (boxes bit for bit, links, counts) and the same primitive order.
inline void expect_same_bvh(const Bvh& expected, const Bvh& got, const std::string& what) {
    ASSERT_EQ(expected.nodes.size(), got.nodes.size()) << what;
    EXPECT_EQ(expected.prim_indices, got.prim_indices) << what;
    size_t wrong = 0;
    for (size_t i = 0; i < expected.nodes.size(); ++i) {
        wrong += !same_box(expected.nodes[i].bounds, got.nodes[i].bounds) ||
                 expected.nodes[i].first != got.nodes[i].first || expected.nodes[i].count != got.nodes[i].count;
    }
    EXPECT_EQ(wrong, 0u) << what << ": nodes that differ";
}

// The soup the hit checks trace, and 4,000 random rays through and around it.
inline SceneGeometry hit_test_soup() {
    return test::make_triangle_soup(5000, 6, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
}

// Closest hits through `bvh` (over `soup`) equal brute force: hit or miss
// and t (the same triangle tests in another order give the same t, maybe
// another triangle at it); at least a tenth of the rays hit.
inline void expect_hits_equal_brute_force(const SceneGeometry& soup, const Bvh& bvh, const std::string& what) {
    const BruteForceAccel brute(soup);
    std::mt19937 rng(17);
    std::uniform_real_distribution<float> u(-12.0f, 12.0f);
    const BvhView view{bvh.nodes.data(), bvh.prim_indices.data(), soup.triangles.data(),
                       static_cast<uint32_t>(bvh.nodes.size())};
    size_t mismatches = 0, hits = 0;
    for (int i = 0; i < 4000; ++i) {
        Ray ray;
        ray.org = Vec3f(u(rng), u(rng), u(rng));
        ray.dir = normalize(Vec3f(u(rng), u(rng), u(rng)) - ray.org + Vec3f(1e-3f, 0.0f, 0.0f));
        const Hit expected = brute.intersect(ray), got = bvh_intersect(view, ray);
        hits += expected.found();
        mismatches += expected.found() != got.found() || (expected.found() && expected.t != got.t);
    }
    EXPECT_GT(hits, 400u) << what;
    EXPECT_EQ(mismatches, 0u) << what;
}

}  // namespace rf::gpu_build_test
