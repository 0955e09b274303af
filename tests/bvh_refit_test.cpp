// BVH refit (accel/bvh/refit.h): after random per-triangle motion the
// parallel refit equals the serial reference bit for bit, every box is the
// exact union of its subtree's triangles, the topology is kept, and hits
// equal brute force on random rays; the wide layouts refitted in place
// (packs and child boxes) trace like brute force, and moved back they are
// the original collapse again; the refit updater of the dynamic accel;
// empty and one-triangle trees.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel/bvh/refit.h"
#include "accel/bvh/refit_steps.h"
#include "accel/update/bvh_updater.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "backend/cpu/wide_bvh_tracer.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

// Each triangle moved by its own random offset up to `shift`, and each
// vertex jittered by up to `jitter` (so triangles deform too). Zero-area
// triangles stay zero-area only by chance: the nasty scene's are jittered
// in most coordinates, its points (v0 = v1 = v2) are moved rigidly.
SceneGeometry moved(const SceneGeometry& g, uint32_t seed, float shift, float jitter) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    SceneGeometry out = g;
    out.bounds = Box3f();
    for (Triangle& t : out.triangles) {
        const Vec3f offset(u(rng) * shift, u(rng) * shift, u(rng) * shift);
        const bool point = t.v0 == t.v1 && t.v1 == t.v2;
        for (Vec3f* v : {&t.v0, &t.v1, &t.v2}) {
            const Vec3f j(u(rng) * jitter, u(rng) * jitter, u(rng) * jitter);
            *v = *v + offset + (point ? Vec3f(0.0f) : j);
        }
        out.bounds.extend(t.bounds());
    }
    return out;
}

bool same_bits(const void* a, const void* b, size_t bytes) { return std::memcmp(a, b, bytes) == 0; }

bool same_nodes(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && same_bits(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode));
}

void expect_same_topology(const Bvh& a, const Bvh& b) {
    ASSERT_EQ(a.nodes.size(), b.nodes.size());
    for (size_t i = 0; i < a.nodes.size(); ++i) {
        EXPECT_EQ(a.nodes[i].first, b.nodes[i].first) << i;
        EXPECT_EQ(a.nodes[i].count, b.nodes[i].count) << i;
    }
    EXPECT_EQ(a.prim_indices, b.prim_indices);
}

void expect_same_hit(const Hit& got, const Hit& expected, size_t ray) {
    ASSERT_EQ(got.found(), expected.found()) << "ray " << ray;
    if (!expected.found()) return;
    if (got.prim != expected.prim) {
        EXPECT_NEAR(got.t, expected.t, 1e-5f * std::fabs(expected.t)) << "ray " << ray;
    } else {
        EXPECT_EQ(got.t, expected.t) << "ray " << ray;
    }
}

// Closest and any hit of `trace` (a Ray -> Hit, a Ray -> bool) against brute force.
template <class Intersect, class Occluded>
void expect_brute_force_hits(const SceneGeometry& g, Intersect&& intersect, Occluded&& occluded, uint32_t seed) {
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = test::make_rays(g, 600, seed);
    size_t hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = brute.intersect(rays[i]);
        expect_same_hit(intersect(rays[i]), expected, i);
        EXPECT_EQ(occluded(rays[i]), expected.found()) << "ray " << i;
        hits += expected.found() ? 1 : 0;
    }
    EXPECT_GT(hits, rays.size() / 5);  // the rays really reach the moved triangles
}

struct Case {
    std::string name;
    SceneGeometry geometry;
};

std::vector<Case> scenes() {
    std::vector<Case> cases;
    cases.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    cases.push_back({"soup", test::make_triangle_soup(3000, 7, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.6f)});
    cases.push_back({"nasty", test::make_nasty_geometry(3)});
    return cases;
}

BuildOptions with_builder(Builder builder, int leaf_size) {
    BuildOptions options;
    options.builder = builder;
    options.max_leaf_size = leaf_size;
    return options;
}

TEST(BvhRefit, ParallelEqualsSerialAndBoxesAreTight) {
    for (const Case& c : scenes()) {
        // SBVH: triangles referenced from several leaves, whose clipped boxes become whole.
        for (Builder builder : {Builder::BinnedSah, Builder::Lbvh30, Builder::Ploc, Builder::Sbvh}) {
            for (int leaf_size : {1, 4}) {
                SCOPED_TRACE(c.name + ", " + to_string(builder) + ", leaves of " + std::to_string(leaf_size));
                const Bvh built = build_bvh_on_cpu(c.geometry.triangles, with_builder(builder, leaf_size));
                const SceneGeometry g = moved(c.geometry, 11, 0.3f, 0.2f);
                Bvh parallel = built, serial = built;
                refit_bvh(parallel, g.triangles);
                refit_bvh_serial(serial, g.triangles);
                EXPECT_TRUE(same_nodes(parallel, serial));
                expect_same_topology(parallel, built);
                // Every box the exact union of its subtree's triangles, and the tree still valid.
                test::check_bvh(parallel, g.triangles, leaf_size,
                                builder == Builder::Sbvh ? test::Refs::Repeated : test::Refs::Once);
                EXPECT_EQ(parallel.nodes[0].bounds.lo, g.bounds.lo);
                EXPECT_EQ(parallel.nodes[0].bounds.hi, g.bounds.hi);
            }
        }
    }
}

TEST(BvhRefit, PlanReusedOverFramesAndCountersReturnToZero) {
    const SceneGeometry start = test::make_triangle_soup(5000, 2, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.3f);
    Bvh bvh = build_bvh_on_cpu(start.triangles, BuildOptions{});
    RefitPlan plan = make_refit_plan(bvh);
    ASSERT_EQ(plan.leaves.size(), bvh.leaf_count());
    EXPECT_EQ(plan.parents[0], refit::kNoParent);
    for (uint32_t frame = 0; frame < 4; ++frame) {
        const SceneGeometry g = moved(start, 100 + frame, 0.5f * float(frame + 1), 0.1f);
        Bvh serial = bvh;
        refit_bvh(bvh, g.triangles, plan);
        refit_bvh_serial(serial, g.triangles);
        EXPECT_TRUE(same_nodes(bvh, serial)) << "frame " << frame;
        for (uint32_t a : plan.arrivals) ASSERT_EQ(a, 0u) << "frame " << frame;
    }
    Bvh other = build_bvh_on_cpu(start.triangles, with_builder(Builder::BinnedSah, 1));
    EXPECT_THROW(refit_bvh(other, start.triangles, plan), Error);
}

TEST(BvhRefit, MovedBackGivesTheBuiltBoxes) {
    // The builders' boxes are the exact unions too, so undoing the motion
    // undoes the refit (the "frame 100 -> 1" direction of Garanzha 2014's tests).
    const SceneGeometry start = test::to_geometry(test::make_icosphere(3));
    const Bvh built = build_bvh_on_cpu(start.triangles, BuildOptions{});
    Bvh bvh = built;
    refit_bvh(bvh, moved(start, 5, 2.0f, 0.5f).triangles);
    EXPECT_FALSE(same_nodes(bvh, built));
    refit_bvh(bvh, start.triangles);
    EXPECT_TRUE(same_nodes(bvh, built));
}

TEST(BvhRefit, HitsEqualBruteForceAfterMotion) {
    for (const Case& c : scenes()) {
        SCOPED_TRACE(c.name);
        Bvh bvh = build_bvh_on_cpu(c.geometry.triangles, BuildOptions{});
        // Large motion: the refitted tree overlaps a lot but must stay exact.
        const SceneGeometry g = moved(c.geometry, 21, 1.5f, 0.3f);
        refit_bvh(bvh, g.triangles);
        const BvhAccel accel(g, std::move(bvh), "bvh/binned/refit", 0.0);
        expect_brute_force_hits(
            g, [&](const Ray& r) { return accel.intersect(r); }, [&](const Ray& r) { return accel.occluded(r); }, 9);
    }
}

TEST(BvhRefit, EmptyAndSingleTriangle) {
    Bvh empty;
    refit_bvh(empty, {});
    refit_bvh_serial(empty, {});
    EXPECT_TRUE(empty.nodes.empty());
    EXPECT_TRUE(make_refit_plan(empty).leaves.empty());

    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    Bvh bvh = build_bvh_on_cpu(one.triangles, BuildOptions{});
    ASSERT_EQ(bvh.nodes.size(), 1u);
    const std::vector<Triangle> moved_one{{Vec3f(2, 3, 4), Vec3f(5, 3, 4), Vec3f(2, 7, -1)}};
    refit_bvh(bvh, moved_one);
    EXPECT_EQ(bvh.nodes[0].bounds.lo, Vec3f(2, 3, -1));
    EXPECT_EQ(bvh.nodes[0].bounds.hi, Vec3f(5, 7, 4));
    EXPECT_EQ(bvh.nodes[0].count, 1u);
}

// ---------------------------------------------------------------------------
// Wide layouts.

template <int N>
Box3f slot_box(const WideNode<N>& node, int c) {
    Box3f b;
    b.lo = Vec3f(node.bounds[0][c], node.bounds[2][c], node.bounds[4][c]);
    b.hi = Vec3f(node.bounds[1][c], node.bounds[3][c], node.bounds[5][c]);
    return b;
}

// Every slot box is exactly the union of its subtree's triangles, and every
// pack lane holds its triangle's coordinates (NaN when zero-area or empty).
template <int N>
Box3f check_wide(const WideBvh<N>& wide, std::span<const Triangle> triangles, uint32_t w, size_t& failures) {
    const WideNode<N>& node = wide.nodes[w];
    Box3f all;
    for (int c = 0; c < N && node.child[c] != kWideEmptyRef; ++c) {
        const uint32_t ref = node.child[c];
        Box3f box;
        if (wide_is_leaf(ref)) {
            for (uint32_t p = wide_leaf_first_pack(ref); p < wide_leaf_first_pack(ref) + wide_leaf_pack_count(ref); ++p) {
                const TrianglePack& pack = wide.packs[p];
                for (int lane = 0; lane < kTrianglePackWidth; ++lane) {
                    if (pack.prim[lane] == kInvalidId) {
                        failures += std::isnan(pack.v[0][0][lane]) ? 0 : 1;
                        continue;
                    }
                    const Triangle& t = triangles[pack.prim[lane]];
                    box.extend(t.bounds());
                    const bool zero = t.geometric_normal() == Vec3f(0.0f);
                    const Vec3f v[3] = {t.v0, t.v1, t.v2};
                    for (int k = 0; k < 3; ++k) {
                        for (int axis = 0; axis < 3; ++axis) {
                            const float f = pack.v[k][axis][lane];
                            failures += (zero ? std::isnan(f) : f == v[k][axis]) ? 0 : 1;
                        }
                    }
                }
            }
        } else {
            box = check_wide(wide, triangles, ref, failures);
        }
        const Box3f slot = slot_box(node, c);
        failures += (slot.lo == box.lo && slot.hi == box.hi) ? 0 : 1;
        all.extend(box);
    }
    return all;
}

template <int N>
void check_wide_refit(const Case& c) {
    SCOPED_TRACE(c.name + ", BVH" + std::to_string(N));
    const Bvh bvh = build_bvh_on_cpu(c.geometry.triangles, BuildOptions{});
    const WideBvh<N> original = collapse_bvh<N>(bvh, c.geometry.triangles);
    WideBvh<N> wide = original;
    const void* nodes = wide.nodes.data();
    const void* packs = wide.packs.data();

    const SceneGeometry g = moved(c.geometry, 31, 4.0f, 0.4f);  // far enough to change coord_scale
    refit_wide_bvh(wide, g.triangles);
    EXPECT_EQ(wide.nodes.data(), nodes);  // in place: views stay valid
    EXPECT_EQ(wide.packs.data(), packs);
    size_t failures = 0;
    const Box3f root = check_wide(wide, g.triangles, 0, failures);
    EXPECT_EQ(failures, 0u);
    float scale = 1.0f;
    for (int axis = 0; axis < 3; ++axis) scale = std::fmax(scale, std::fmax(std::fabs(root.lo[axis]), std::fabs(root.hi[axis])));
    EXPECT_EQ(wide.coord_scale, scale);
    for (size_t i = 0; i < wide.nodes.size(); ++i) {
        ASSERT_TRUE(same_bits(wide.nodes[i].child, original.nodes[i].child, sizeof original.nodes[i].child));
    }

    const WideBvhTracer<N> tracer{WideBvhView<N>{wide.nodes.data(), wide.packs.data(), uint32_t(wide.nodes.size()),
                                                 wide.coord_scale}};
    expect_brute_force_hits(
        g, [&](const Ray& r) { return tracer.intersect(r); }, [&](const Ray& r) { return tracer.occluded(r); }, 4);

    // Moved back: the original collapse, bit for bit (its boxes are the
    // binary tree's, which are the exact unions too).
    refit_wide_bvh(wide, c.geometry.triangles);
    EXPECT_EQ(wide.coord_scale, original.coord_scale);
    EXPECT_TRUE(same_bits(wide.nodes.data(), original.nodes.data(), wide.nodes.size() * sizeof(WideNode<N>)));
    EXPECT_TRUE(same_bits(wide.packs.data(), original.packs.data(), wide.packs.size() * sizeof(TrianglePack)));
}

TEST(BvhRefitWide, RefittedInPlaceTracesLikeBruteForce) {
    for (const Case& c : scenes()) {
        check_wide_refit<4>(c);
        check_wide_refit<8>(c);
    }
}

TEST(BvhRefitWide, EmptyAndSingleTriangle) {
    WideBvh<8> empty;
    refit_wide_bvh(empty, {});
    EXPECT_TRUE(empty.nodes.empty());

    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    WideBvh<4> wide = collapse_bvh<4>(build_bvh_on_cpu(one.triangles, BuildOptions{}), one.triangles);
    const std::vector<Triangle> far{{Vec3f(-7, 3, 4), Vec3f(5, 3, 4), Vec3f(2, 7, -1)}};
    refit_wide_bvh(wide, far);
    size_t failures = 0;
    check_wide(wide, far, 0, failures);
    EXPECT_EQ(failures, 0u);
    EXPECT_EQ(wide.coord_scale, 7.0f);
    // Degenerate now: the pack's lane turns NaN, as collapse_bvh writes it.
    const std::vector<Triangle> flat{{Vec3f(1, 1, 1), Vec3f(2, 2, 2), Vec3f(3, 3, 3)}};
    refit_wide_bvh(wide, flat);
    EXPECT_TRUE(std::isnan(wide.packs[0].v[0][0][0]));
    EXPECT_EQ(wide.packs[0].prim[0], 0u);
}

// ---------------------------------------------------------------------------
// The dynamic accel's refit method.

TEST(BvhRefitUpdater, BuildsOnceThenRefits) {
    const SceneGeometry start = test::to_geometry(test::make_icosphere(3));
    BuildOptions options;
    options.threads = 2;
    const auto updater = make_refit_updater(start.triangles, options);
    const Bvh built = build_bvh_on_cpu(start.triangles, options);
    EXPECT_TRUE(same_nodes(updater->bvh(), built));
    for (uint32_t frame = 0; frame < 3; ++frame) {
        const SceneGeometry g = moved(start, 40 + frame, 0.2f, 0.05f);
        UpdateStats stats;
        EXPECT_FALSE(updater->update(g.triangles, stats));  // topology kept
        EXPECT_EQ(stats.refitted_nodes, built.nodes.size());
        Bvh expected = built;
        refit_bvh_serial(expected, g.triangles);
        EXPECT_TRUE(same_nodes(updater->bvh(), expected)) << "frame " << frame;
    }
    UpdateStats stats;
    EXPECT_THROW(updater->update(std::span<const Triangle>(start.triangles).first(10), stats), Error);
}

}  // namespace
}  // namespace rf
