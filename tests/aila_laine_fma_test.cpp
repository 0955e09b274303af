// The aila-laine-fma node-pair traversal (trace/aila_laine_fma_traversal.h):
// its hits against the classic traversal (bit for bit) and brute force over
// procedural scenes and adversarial rays, the FMA slab test against an exact
// (double precision) slab test, host replays of the persistent kernel's
// dynamic-fetch schedule, and the node-fetch counters.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "aila_laine_test_support.h"
#include "rayforge/accel/accel.h"
#include "trace/aila_laine_fma_traversal.h"
#include "trace/tracers.h"

namespace rf {
namespace {

using test::AlwaysRefillWarp;
using test::expect_same_closest;
using test::NeverReadyWarp;
using test::RandomRefillWarp;
using test::trace_like_persistent_warp;

// Whether the ray meets the closed box at some t in [tmin, tmax], in double
// precision (a zero direction component: the origin within that slab).
bool exact_enters(const Ray& ray, const Box3f& box) {
    double t0 = ray.tmin, t1 = ray.tmax;
    for (int a = 0; a < 3; ++a) {
        const double o = ray.org[a], d = ray.dir[a], lo = box.lo[a], hi = box.hi[a];
        if (d == 0.0) {
            if (o < lo || o > hi) return false;
            continue;
        }
        double near = (lo - o) / d, far = (hi - o) / d;
        if (near > far) std::swap(near, far);
        t0 = std::max(t0, near);
        t1 = std::min(t1, far);
    }
    return t0 <= t1;
}

// Hits of the two node-pair traversals: the same triangle with the same
// bits, or, where two triangles lie at exactly the same distance (a shared
// edge), the same t (which of them wins depends on the order the boxes are
// entered, which the two box tests may break differently). Returns 1 for such a tie.
int expect_same_hit_bits(const Hit& fma, const Hit& classic) {
    EXPECT_EQ(fma.found(), classic.found());
    if (!fma.found() || !classic.found()) return 0;
    EXPECT_EQ(std::bit_cast<uint32_t>(fma.t), std::bit_cast<uint32_t>(classic.t));
    if (fma.prim != classic.prim) return 1;
    EXPECT_EQ(std::bit_cast<uint32_t>(fma.u), std::bit_cast<uint32_t>(classic.u));
    EXPECT_EQ(std::bit_cast<uint32_t>(fma.v), std::bit_cast<uint32_t>(classic.v));
    return 0;
}

// Rays aimed at what box tests get wrong, from the canonical BVH's boxes:
// corners and edge midpoints, origins on box planes, axis-parallel rays along
// box faces, directions with zero or tiny components, [tmin, tmax] clipped
// to a box's own entry and exit, negative tmin.
std::vector<Ray> adversarial_rays(const SceneGeometry& g, const Bvh& bvh, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<size_t> pick_node(0, bvh.nodes.size() - 1);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const Vec3f margin = g.bounds.extent() * 0.5f + Vec3f(1e-3f * max_component(g.bounds.extent()));
    const Box3f around{g.bounds.lo - margin, g.bounds.hi + margin};
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        const Box3f box = bvh.nodes[pick_node(rng)].bounds;
        auto corner = [&](uint32_t bits) {
            return Vec3f(bits & 1 ? box.hi.x : box.lo.x, bits & 2 ? box.hi.y : box.lo.y, bits & 4 ? box.hi.z : box.lo.z);
        };
        const Vec3f inside = box.lo + (box.hi - box.lo) * Vec3f(unit(rng), unit(rng), unit(rng));
        const int axis = int(i % 3);
        Ray ray;
        ray.org = test::random_in_box(rng, around);
        switch (i % 9) {
            case 0: ray.dir = corner(uint32_t(rng()) & 7u) - ray.org; break;
            case 1: ray.dir = (corner(uint32_t(rng()) & 7u) + corner(uint32_t(rng()) & 7u)) * 0.5f - ray.org; break;
            case 2: {  // origin on a box plane, inside the face
                ray.org = inside;
                ray.org[axis] = (i & 8) ? box.hi[axis] : box.lo[axis];
                ray.dir = test::random_direction(rng);
                break;
            }
            case 3: {  // axis-parallel along a face or an edge of the box
                ray.org = inside;
                const int b = (axis + 1) % 3;
                ray.org[b] = (i & 8) ? box.hi[b] : box.lo[b];
                if (i & 16) ray.org[(axis + 2) % 3] = box.lo[(axis + 2) % 3];
                ray.org[axis] = (i & 32) ? around.lo[axis] : around.hi[axis];
                ray.dir = Vec3f(0.0f);
                ray.dir[axis] = (i & 32) ? 1.0f : -1.0f;
                break;
            }
            case 4: {  // one tiny, one zero component
                ray.dir = inside - ray.org;
                ray.dir[axis] = (i & 8) ? 1e-30f : -1e-38f;
                ray.dir[(axis + 1) % 3] = (i & 16) ? 0.0f : -0.0f;
                break;
            }
            case 5: {  // [tmin, tmax] clipped to the box's own entry and exit
                ray.dir = inside - ray.org;
                double t0 = 0.0, t1 = 1e30;
                for (int a = 0; a < 3; ++a) {
                    if (ray.dir[a] == 0.0f) continue;
                    double n = (double(box.lo[a]) - ray.org[a]) / ray.dir[a], f = (double(box.hi[a]) - ray.org[a]) / ray.dir[a];
                    if (n > f) std::swap(n, f);
                    t0 = std::max(t0, n);
                    t1 = std::min(t1, f);
                }
                ray.tmin = float(t0);
                ray.tmax = (i & 8) ? float(t1) : float(t0);
                break;
            }
            case 6: {  // negative tmin, the origin past the box
                ray.dir = ray.org - inside;
                ray.tmin = -2.0f - 3.0f * unit(rng);
                ray.tmax = (i & 8) ? kInfinity : 0.5f;
                break;
            }
            // Long and short directions (t scaled by 1e4 either way; much more
            // and the watertight test's products under- or overflow on the
            // tiny and huge scenes, where it then answers t = 0 for any triangle).
            case 7: ray.dir = test::random_direction(rng) * ((i & 8) ? 1e-4f : 1e4f); break;
            case 8: {  // through a shared vertex or edge of two triangles (tessellated meshes)
                const Triangle& tri = g.triangles[rng() % g.triangles.size()];
                ray.dir = ((i & 8) ? tri.v0 : (tri.v0 + tri.v1) * 0.5f) - ray.org;
                break;
            }
        }
        if (length_squared(ray.dir) == 0.0f) ray.dir = Vec3f(0, 0, 1);
        rays.push_back(ray);
    }
    return rays;
}

// The persistent kernel's dynamic-fetch vote as a host replay sees it: the
// lanes of the simulated warp still holding a ray stand for __activemask().
struct SimulatedWarpVote {
    static inline int traversing = 32;
    static inline uint64_t yields = 0;
    static bool any_searching(bool searching) { return searching; }
    static bool yield_for_refill() {
        const bool yield = traversing < kAilaLaineDynamicFetchThreshold;
        yields += yield;
        return yield;
    }
};

// The schedule of aila_laine_persistent_kernel on the host: `warps` warps of
// 32 lanes, each pass of a warp refilling its idle lanes from one shared ray
// counter (ranks by a prefix count, as the ballot and popc do), lanes leaving
// for good once the counter passes the rays, every lane with a ray resuming.
template <bool kAnyHit, class Traversal>
std::vector<Hit> replay_persistent_kernel(const AilaLaineView& view, const std::vector<Ray>& rays, int warps,
                                          std::vector<int>& writes) {
    constexpr int kLanes = 32;
    struct Lane {
        typename Traversal::State state;
        uint32_t ray = 0;
        bool has_ray = false;
        bool exited = false;
    };
    std::vector<std::vector<Lane>> lanes(static_cast<size_t>(warps), std::vector<Lane>(kLanes));
    std::vector<Hit> out(rays.size());
    writes.assign(rays.size(), 0);
    uint32_t next_ray = 0;
    const auto count = uint32_t(rays.size());
    for (bool running = true; running;) {
        running = false;
        for (std::vector<Lane>& warp : lanes) {
            uint32_t needing = 0;
            for (int l = 0; l < kLanes; ++l) needing += !warp[size_t(l)].exited && !warp[size_t(l)].has_ray;
            const uint32_t base = next_ray;
            next_ray += needing;
            uint32_t rank = 0;
            int holding = 0;
            for (Lane& lane : warp) {
                if (lane.exited || lane.has_ray) continue;
                lane.ray = base + rank++;
                if (lane.ray >= count) {
                    lane.exited = true;
                    continue;
                }
                Traversal::begin(view, rays[lane.ray], lane.state);
                lane.has_ray = true;
            }
            for (const Lane& lane : warp) holding += lane.has_ray;
            for (Lane& lane : warp) {
                if (!lane.has_ray) continue;
                running = true;
                SimulatedWarpVote::traversing = holding;
                if (Traversal::template resume<kAnyHit, false, SimulatedWarpVote>(view, lane.state, nullptr)) {
                    out[lane.ray] = lane.state.hit;
                    ++writes[lane.ray];
                    lane.has_ray = false;
                    --holding;
                }
            }
        }
    }
    return out;
}

struct CompareCounts {
    size_t hits = 0, ties = 0, unusable = 0, negative_tmin = 0;
};

// The fma variant against the classic traversal and brute force on `rays`.
void compare_rays(const AilaLaineView& view, const BruteForceAccel& brute, const std::vector<Ray>& rays,
                  CompareCounts& counts) {
    for (const Ray& ray : rays) {
        const Hit expected = brute.intersect(ray);
        const Hit classic = aila_laine_intersect(view, ray);
        const Hit fma = aila_laine_fma_intersect(view, ray);
        const bool usable = detail::FmaSlabRay::make(ray).usable;
        counts.unusable += !usable;
        // The classic slab test scales t_far by 1 + 2 gamma(3), which shrinks
        // a negative t_far: with tmin < 0 it may cull boxes behind the origin
        // that hold hits. The FMA test pads for that (its tmin term), so with
        // tmin < 0 brute force decides; rays it cannot serve take the classic
        // test, and then equal the classic traversal instead.
        const bool classic_exact = ray.tmin >= 0.0f;
        if (classic_exact || !usable) {
            counts.ties += size_t(expect_same_hit_bits(fma, classic));
            EXPECT_EQ(aila_laine_fma_occluded(view, ray), aila_laine_occluded(view, ray));
        }
        if (!classic_exact) ++counts.negative_tmin;
        if (classic_exact || usable) {
            expect_same_closest(fma, expected, ray);
            EXPECT_EQ(aila_laine_fma_occluded(view, ray), expected.found());
        }
        TraversalCounters counters;
        const Hit counted = aila_laine_fma_intersect_counted(view, ray, counters);
        EXPECT_EQ(std::bit_cast<uint32_t>(counted.t), std::bit_cast<uint32_t>(fma.t));
        EXPECT_EQ(counted.prim, fma.prim);
        EXPECT_EQ(counters.nodes_visited, 2 * counters.node_fetches);
        const bool any = aila_laine_fma_occluded(view, ray);
        EXPECT_EQ(aila_laine_fma_occluded_counted(view, ray, counters), any);
        const Hit speculative = detail::aila_laine_fma_traverse<false, false, NeverReadyWarp>(view, ray, nullptr);
        counts.ties += size_t(expect_same_hit_bits(speculative, fma));
        EXPECT_EQ((detail::aila_laine_fma_traverse<true, false, NeverReadyWarp>(view, ray, nullptr).found()), any);
        counts.hits += expected.found();
    }
}

// Every ray's result written once and equal to the one-ray traversal's.
void compare_replays(const AilaLaineView& view, const std::vector<Ray>& rays) {
    std::vector<int> writes;
    const auto once = [&] { return std::count(writes.begin(), writes.end(), 1); };
    std::vector<Hit> single(rays.size());
    std::vector<uint8_t> single_any(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) {
        single[i] = aila_laine_fma_intersect(view, rays[i]);
        single_any[i] = aila_laine_fma_occluded(view, rays[i]);
    }
    auto check = [&](const std::vector<Hit>& got, bool any_hit, const char* what) {
        SCOPED_TRACE(what);
        EXPECT_EQ(once(), ptrdiff_t(rays.size()));
        for (size_t i = 0; i < rays.size(); ++i) {
            if (any_hit) {
                EXPECT_EQ(got[i].found(), single_any[i] != 0);
            } else {
                // Speculation and yields change no decision of a ray's own traversal.
                EXPECT_EQ(std::bit_cast<uint32_t>(got[i].t), std::bit_cast<uint32_t>(single[i].t));
                EXPECT_EQ(got[i].prim, single[i].prim);
            }
        }
    };
    using Fma = AilaLaineFmaTraversal;
    check(trace_like_persistent_warp<false, AlwaysRefillWarp, Fma>(view, rays, writes), false, "always refill");
    check(trace_like_persistent_warp<false, RandomRefillWarp, Fma>(view, rays, writes), false, "random refill");
    check(trace_like_persistent_warp<true, RandomRefillWarp, Fma>(view, rays, writes), true, "random refill, any");
    const uint64_t yields_before = SimulatedWarpVote::yields;
    for (int warps : {1, 3}) {
        check(replay_persistent_kernel<false, Fma>(view, rays, warps, writes), false, "kernel schedule");
        check(replay_persistent_kernel<true, Fma>(view, rays, warps, writes), true, "kernel schedule, any");
    }
    if (view.node_count > 0) EXPECT_GT(SimulatedWarpVote::yields, yields_before);  // the pool's tail yields
}

void compare_scene(const SceneGeometry& g, const BuildOptions& options, size_t ray_count, uint32_t seed) {
    const Bvh bvh = build_bvh(g.triangles, options);
    const AilaLaineBvh al = convert_to_aila_laine(bvh, g.triangles);
    const AilaLaineView view = al.view();
    const BruteForceAccel brute(g);
    CompareCounts counts;
    const std::vector<Ray> random = test::make_rays(g, ray_count, seed);
    compare_rays(view, brute, random, counts);
    EXPECT_GT(counts.hits, ray_count / 5);
    EXPECT_LT(counts.hits, ray_count);
    const std::vector<Ray> adversarial = adversarial_rays(g, bvh, ray_count, seed + 100);
    compare_rays(view, brute, adversarial, counts);
    EXPECT_GT(counts.unusable, 0u);                    // the classic-slab fallback ran
    EXPECT_GT(counts.negative_tmin, 0u);
    EXPECT_LT(counts.ties, 2 * ray_count / 100 + 2);   // ties are shared edges, rare
    compare_replays(view, random);
}

constexpr Builder kBuilders[] = {Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh30};

TEST(AilaLaineFma, MatchesClassicAndBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 31, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    for (Builder builder : kBuilders) {
        for (int leaf : {1, 4}) {
            SCOPED_TRACE(to_string(builder) + " leaf " + std::to_string(leaf));
            compare_scene(soup, BuildOptions{.builder = builder, .max_leaf_size = leaf}, 1000, 11);
        }
    }
}

TEST(AilaLaineFma, MatchesClassicAndBruteForceOnTessellatedMeshes) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(to_string(builder));
        compare_scene(cube, BuildOptions{.builder = builder, .max_leaf_size = 2}, 1500, 12);
        compare_scene(sphere, BuildOptions{.builder = builder}, 1500, 13);
    }
}

TEST(AilaLaineFma, MatchesClassicAndBruteForceOnDegenerateTriangles) {
    const SceneGeometry nasty = test::make_nasty_geometry(5);
    for (Builder builder : kBuilders) {
        SCOPED_TRACE(to_string(builder));
        compare_scene(nasty, BuildOptions{.builder = builder, .max_leaf_size = 2}, 1500, 14);
    }
}

TEST(AilaLaineFma, MatchesClassicAndBruteForceAtHugeAndTinyScales) {
    const SceneGeometry far = test::make_triangle_soup(1500, 32, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    const SceneGeometry huge = test::make_triangle_soup(1500, 33, {Vec3f(-1e15f), Vec3f(1e15f)}, 3e13f);
    // (Much smaller and the watertight test's products underflow: it then
    // reports hits at t = 0 that no box holds, for the classic traversal too.)
    const SceneGeometry tiny = test::make_triangle_soup(1500, 34, {Vec3f(-1e-9f), Vec3f(1e-9f)}, 1e-10f);
    const SceneGeometry off = test::to_geometry(test::make_tessellated_cube(6), 0.5f, Vec3f(4e4f, -3e4f, 1e4f));
    for (const SceneGeometry* g : {&far, &huge, &tiny, &off}) {
        SCOPED_TRACE(g == &far ? "far" : g == &huge ? "huge" : g == &tiny ? "tiny" : "off");
        compare_scene(*g, BuildOptions{}, 1500, 15);
        compare_scene(*g, BuildOptions{.builder = Builder::Sbvh, .max_leaf_size = 1}, 1000, 16);
    }
}

// The property the traversal's equality rests on: the FMA test never culls a
// box that the ray enters within [tmin, tmax] by the exact test, over boxes of
// real trees, random, flat and point boxes, and the adversarial rays above.
TEST(AilaLaineFma, FmaSlabTestNeverCullsAnEnteredBox) {
    std::mt19937 rng(40);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    size_t checked = 0, entered = 0, loose = 0;
    for (float scale : {1e-20f, 1e-3f, 1.0f, 1e4f, 1e12f}) {
        const SceneGeometry soup =
            test::make_triangle_soup(400, 41, {Vec3f(-10.0f * scale), Vec3f(10.0f * scale)}, 0.7f * scale);
        const Bvh bvh = build_bvh(soup.triangles, BuildOptions{.max_leaf_size = 1});
        std::vector<Box3f> boxes;
        for (const BvhNode& n : bvh.nodes) boxes.push_back(n.bounds);
        for (int i = 0; i < 200; ++i) {
            const Vec3f c = Vec3f(unit(rng), unit(rng), unit(rng)) * (10.0f * scale);
            const Vec3f h = abs(Vec3f(unit(rng), unit(rng), unit(rng))) * scale;
            Box3f b{c - h, c + h};
            if (i % 4 == 1) b.hi.y = b.lo.y;   // flat
            if (i % 4 == 2) b.hi = b.lo;       // a point
            boxes.push_back(b);
        }
        std::vector<Ray> rays = adversarial_rays(soup, bvh, 600, 42);
        const std::vector<Ray> more = test::make_rays(soup, 300, 43);
        rays.insert(rays.end(), more.begin(), more.end());
        for (const Ray& ray : rays) {
            const detail::FmaSlabRay fma = detail::FmaSlabRay::make(ray);
            if (!fma.usable) continue;
            for (const Box3f& box : boxes) {
                float entry;
                const bool test = detail::fma_slab_test(fma, box, ray.tmin, ray.tmax, entry);
                const bool exact = exact_enters(ray, box);
                ++checked;
                entered += exact;
                // (make_rays' origins lie 1e-3 from the 1e-20 scene, where no
                // float form resolves its boxes: not counted as loose there.)
                loose += test && !exact && scale > 1e-20f;
                if (exact && !test) {
                    ADD_FAILURE() << "culled: org (" << ray.org.x << ", " << ray.org.y << ", " << ray.org.z
                                  << ") dir (" << ray.dir.x << ", " << ray.dir.y << ", " << ray.dir.z << ") ["
                                  << ray.tmin << ", " << ray.tmax << "] box (" << box.lo.x << ", " << box.lo.y
                                  << ", " << box.lo.z << ")-(" << box.hi.x << ", " << box.hi.y << ", " << box.hi.z
                                  << ")";
                    return;
                }
            }
        }
    }
    EXPECT_GT(checked, 1000000u);
    EXPECT_GT(entered, checked / 50);
    EXPECT_LT(loose, checked / 100);  // the pad enters few boxes the ray misses
}

TEST(AilaLaineFma, ZeroDirectionComponentsTakeTheClassicSlabTest) {
    EXPECT_TRUE(detail::FmaSlabRay::make(Ray{Vec3f(1, 2, 3), 0.0f, Vec3f(1, -2, 0.5f)}).usable);
    EXPECT_FALSE(detail::FmaSlabRay::make(Ray{Vec3f(1, 2, 3), 0.0f, Vec3f(1, 0, 0.5f)}).usable);
    EXPECT_FALSE(detail::FmaSlabRay::make(Ray{Vec3f(1, 2, 3), 0.0f, Vec3f(1, -0.0f, 0.5f)}).usable);
    EXPECT_FALSE(detail::FmaSlabRay::make(Ray{Vec3f(1e30f, 2, 3), 0.0f, Vec3f(1e-20f, 1, 1)}).usable);  // ood overflows
    EXPECT_FALSE(detail::FmaSlabRay::make(Ray{Vec3f(1, 2, 3), -std::numeric_limits<float>::infinity(),
                                              Vec3f(1, 1, 1)})
                     .usable);  // the tmin pad overflows
    // An origin exactly on the face of a box, moving along it: entered by both.
    const Box3f box{Vec3f(0.0f), Vec3f(1.0f)};
    const Ray along{Vec3f(0.0f, 0.5f, -1.0f), 0.0f, Vec3f(0, 0, 1)};
    float entry;
    EXPECT_TRUE(detail::slab_test(detail::exact_slab_ray(detail::FmaSlabRay::make(along), along.org), box, along.tmin,
                                  along.tmax, entry));
}

TEST(AilaLaineFma, EmptyAndSingleLeafTrees) {
    const std::vector<Triangle> none;
    const AilaLaineBvh empty = convert_to_aila_laine(build_bvh(none, BuildOptions{}), none);
    const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(aila_laine_fma_intersect(empty.view(), ray).found());
    EXPECT_FALSE(aila_laine_fma_occluded(AilaLaineView{}, ray));
    SceneGeometry g;
    test::append(g, {Vec3f(-1, -1, 0), Vec3f(1, -1, 0), Vec3f(0, 1, 0)});
    const AilaLaineBvh one = convert_to_aila_laine(build_bvh(g.triangles, BuildOptions{}), g.triangles);
    const Ray hit_ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1)};
    const Hit hit = aila_laine_fma_intersect(one.view(), hit_ray);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.t, 2.0f);
    TraversalCounters counters;
    (void)aila_laine_fma_intersect_counted(one.view(), hit_ray, counters);
    EXPECT_EQ(counters.node_fetches, 0u);  // a leaf root: no node pair
    EXPECT_EQ(counters.prims_tested, 1u);
}

// Node fetches reach every counting path: the tracers' RayCounters and the
// CPU accels' TraversalTotals (binary BVH: one per inner node entered and
// the root's box; wide BVH: one per wide node, as its box-test count).
TEST(AilaLaineFma, NodeFetchCounters) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(3));
    const std::vector<Ray> rays = test::make_rays(sphere, 300, 50);
    const AilaLaineBvh al = convert_to_aila_laine(build_bvh(sphere.triangles, BuildOptions{}), sphere.triangles);
    const AilaLaineFmaTracer fma{al.view()};
    const AilaLaineTracer classic{al.view()};
    RayCounters fma_counts, classic_counts;
    for (const Ray& ray : rays) {
        (void)fma.counted(ray, false, fma_counts);
        (void)classic.counted(ray, false, classic_counts);
    }
    EXPECT_GT(fma_counts.node_fetches, rays.size());
    EXPECT_EQ(fma_counts.steps, 2 * fma_counts.node_fetches);
    EXPECT_EQ(classic_counts.steps, 2 * classic_counts.node_fetches);
    // Only culling differs, and only by entering more.
    EXPECT_GE(fma_counts.node_fetches, classic_counts.node_fetches);
    EXPECT_LT(fma_counts.node_fetches, classic_counts.node_fetches + classic_counts.node_fetches / 100 + 10);

    const auto bvh2 = build_accel(sphere, BuildOptions{.layout = Layout::Bvh2});
    TraversalTotals binary;
    ASSERT_TRUE(bvh2->count_traversal(rays, false, binary));
    EXPECT_GT(binary.node_fetches, 0u);
    EXPECT_LT(binary.node_fetches, binary.steps);
    EXPECT_EQ(binary.steps + rays.size(), 2 * binary.node_fetches);  // the root: 1 test, 1 fetch; 2 tests a pair
    const auto bvh8 = build_accel(sphere, BuildOptions{.layout = Layout::Bvh8});
    TraversalTotals wide;
    ASSERT_TRUE(bvh8->count_traversal(rays, false, wide));
    EXPECT_EQ(wide.node_fetches, wide.steps);
    TraversalTotals sum = binary;
    sum += wide;
    EXPECT_EQ(sum.node_fetches, binary.node_fetches + wide.node_fetches);
}

}  // namespace
}  // namespace rf
