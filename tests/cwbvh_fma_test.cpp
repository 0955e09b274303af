// The cwbvh-fma traversal (trace/cwbvh_fma_traversal.h): the compressed wide
// BVH traced as Ylitie, Karras and Laine 2017 do it (one FMA per child plane
// in the node's quantised frame, byte-parallel child masks, vector node
// loads). Its hits must be those of the slab-test cwbvh traversal and of
// brute force, bit for bit, on random scenes and adversarial rays; its
// per-node child test must never cull a child whose dequantised box the
// exact (double) slab test says the ray enters; the four-at-a-time mask
// arithmetic must equal the per-child rule for every meta byte and octant;
// the node words must hold the node's fields; and it must fetch the same
// nodes as the slab-test traversal up to its (conservative) pad.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "trace/cwbvh_fma_traversal.h"
#include "trace/cwbvh_traversal.h"

namespace rf {
namespace {

uint32_t bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
}

// The exact ray against `box` within [tmin, tmax], in double: a zero
// direction component keeps the ray in the slab or never in it.
bool exact_ray_enters(const Box3f& box, const Ray& ray) {
    double t_near = ray.tmin, t_far = ray.tmax;
    for (int a = 0; a < 3; ++a) {
        const double o = ray.org[a], d = ray.dir[a], lo = box.lo[a], hi = box.hi[a];
        if (d == 0.0) {
            if (o < lo || o > hi) return false;
            continue;
        }
        double t0 = (lo - o) / d, t1 = (hi - o) / d;
        if (t0 > t1) std::swap(t0, t1);
        t_near = std::max(t_near, t0);
        t_far = std::min(t_far, t1);
    }
    return t_near <= t_far;
}

// The bits child `slot` of `node` sets in the hit mask when hit (the per-child rule).
uint32_t slot_hit_bits(const CwbvhNode& node, int slot, uint32_t oct_inv) {
    const uint32_t meta = node.meta[slot];
    const uint32_t index = cwbvh_meta_is_inner(uint8_t(meta)) ? (meta ^ oct_inv) & 31u : meta & 31u;
    return (meta >> 5) << index;
}

uint32_t oct_inv_of(const Ray& ray) { return 7u - detail::CwbvhFmaRay::make(ray).octant; }

uint32_t fma_child_hits(const CwbvhBvh& cw, uint32_t index, const Ray& ray) {
    const detail::CwbvhNodeWords words = detail::cwbvh_load_node_words(cw.nodes.data(), index);
    return detail::cwbvh_fma_child_hits(words, detail::CwbvhFmaRay::make(ray), oct_inv_of(ray), ray.tmin, ray.tmax);
}

// Culling statistics of the per-node test against the exact one.
struct CullStats {
    size_t entered = 0;        // slots the exact test says the ray enters
    size_t missed = 0;         // slots it says the ray misses
    size_t extra_accepts = 0;  // of those, accepted by the per-node test (its pad)
};

// Checks every occupied slot of node `index` for `ray`: exactly entered
// implies accepted (never a false cull).
void check_node_never_culls(const CwbvhBvh& cw, uint32_t index, const Ray& ray, CullStats& stats) {
    const CwbvhNode& node = cw.nodes[index];
    const uint32_t hits = fma_child_hits(cw, index, ray);
    const uint32_t oct_inv = oct_inv_of(ray);
    for (int slot = 0; slot < kCwbvhWidth; ++slot) {
        if (node.meta[slot] == kCwbvhEmptyMeta) continue;
        const uint32_t slot_bits = slot_hit_bits(node, slot, oct_inv);
        const bool accepted = (hits & slot_bits) == slot_bits;
        if (exact_ray_enters(cwbvh_child_box(node, slot), ray)) {
            ++stats.entered;
            if (!accepted) {
                const Box3f b = cwbvh_child_box(node, slot);
                ADD_FAILURE() << "node " << index << " slot " << slot << " culled; org " << ray.org.x << ' '
                              << ray.org.y << ' ' << ray.org.z << " dir " << ray.dir.x << ' ' << ray.dir.y << ' '
                              << ray.dir.z << " t [" << ray.tmin << ", " << ray.tmax << "] box " << b.lo.x << ' '
                              << b.lo.y << ' ' << b.lo.z << " .. " << b.hi.x << ' ' << b.hi.y << ' ' << b.hi.z;
            }
        } else {
            ++stats.missed;
            stats.extra_accepts += accepted;
        }
    }
}

// Rays that graze the dequantised child boxes of `node`: along their faces
// and edges (axis-parallel, origin on a plane), through their corners, from
// inside and from their faces, with tmin / tmax at the box's exact entry and
// exit, plus tiny and zero direction components.
std::vector<Ray> grazing_rays(const CwbvhNode& node, std::mt19937& rng) {
    std::vector<Ray> rays;
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    for (int slot = 0; slot < kCwbvhWidth; ++slot) {
        if (node.meta[slot] == kCwbvhEmptyMeta) continue;
        const Box3f b = cwbvh_child_box(node, slot);
        const Vec3f e = b.extent() + Vec3f(1e-6f);
        const Vec3f corner(unit(rng) < 0.5f ? b.lo.x : b.hi.x, unit(rng) < 0.5f ? b.lo.y : b.hi.y,
                           unit(rng) < 0.5f ? b.lo.z : b.hi.z);
        const Vec3f outside = b.lo - e * (0.5f + unit(rng)) + Vec3f(unit(rng), unit(rng), unit(rng)) * e * 3.0f;
        const Vec3f inside = test::random_in_box(rng, b);
        // Through a corner from outside, and from inside to the corner.
        rays.push_back(Ray{outside, 0.0f, corner - outside});
        rays.push_back(Ray{inside, 0.0f, corner - inside});
        // From the corner (origin on the box) in a random direction.
        rays.push_back(Ray{corner, 0.0f, test::random_direction(rng)});
        // Axis-parallel along a face: origin on a face plane, direction along another axis.
        for (int a = 0; a < 3; ++a) {
            Vec3f org = inside;
            org[a] = unit(rng) < 0.5f ? b.lo[a] : b.hi[a];
            const int along = (a + 1 + int(unit(rng) * 2.0f)) % 3;
            org[along] = b.lo[along] - e[along];
            Vec3f dir(0.0f);
            dir[along] = 1.0f;
            rays.push_back(Ray{org, 0.0f, dir});
            Vec3f back(0.0f);
            back[along] = -1.0f;
            org[along] = b.hi[along] + e[along];
            rays.push_back(Ray{org, 0.0f, back});
            // Along an edge: two coordinates on planes.
            Vec3f edge_org = org;
            const int other = 3 - a - along;
            edge_org[other] = unit(rng) < 0.5f ? b.lo[other] : b.hi[other];
            rays.push_back(Ray{edge_org, 0.0f, back});
            // A tiny (non-zero) component across the plane.
            Vec3f tilted = back;
            tilted[a] = (unit(rng) < 0.5f ? -1.0f : 1.0f) * 1e-30f;
            rays.push_back(Ray{org, 0.0f, tilted});
        }
        // tmin / tmax clipped at the entry and exit of the box (float rounding either way).
        Ray clipped{outside, 0.0f, inside - outside};
        double t_near = 0.0, t_far = 1e30;
        for (int a = 0; a < 3; ++a) {
            if (clipped.dir[a] == 0.0f) continue;
            double t0 = (double(b.lo[a]) - clipped.org[a]) / clipped.dir[a];
            double t1 = (double(b.hi[a]) - clipped.org[a]) / clipped.dir[a];
            if (t0 > t1) std::swap(t0, t1);
            t_near = std::max(t_near, t0);
            t_far = std::min(t_far, t1);
        }
        if (t_near <= t_far) {
            Ray to_entry = clipped;
            to_entry.tmax = float(t_near);
            rays.push_back(to_entry);
            to_entry.tmax = std::nextafter(float(t_near), 0.0f);
            rays.push_back(to_entry);
            Ray from_exit = clipped;
            from_exit.tmin = float(t_far);
            rays.push_back(from_exit);
            from_exit.tmin = std::nextafter(float(t_far), 1e30f);
            rays.push_back(from_exit);
        }
    }
    return rays;
}

// Scenes of the traversal tests: soup, closed meshes, degenerate triangles,
// far from the origin, huge and tiny.
struct NamedScene {
    std::string name;
    SceneGeometry g;
};
std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    scenes.push_back({"cube", test::to_geometry(test::make_tessellated_cube(8))});
    scenes.push_back({"nasty", test::make_nasty_geometry(5)});
    scenes.push_back({"far", test::make_triangle_soup(1500, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f)});
    scenes.push_back({"huge", test::make_triangle_soup(1500, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f)});
    // (Surface areas stay finite and normal in float: the SAH builders need them.)
    scenes.push_back({"tiny", test::to_geometry(test::make_icosphere(3), 1e-12f, Vec3f(3e-12f))});
    scenes.push_back({"vast", test::to_geometry(test::make_icosphere(3), 1e15f, Vec3f(-2e15f, 0.0f, 5e14f))});
    return scenes;
}

// A postponement policy that postpones whenever asked.
struct AlwaysPostpone {
    void begin_iteration() {}
    bool postpone() { return true; }
    void pushed(int size) { EXPECT_LE(size, kCwbvhTraversalStackSize); }
};

constexpr Builder kBuilders[] = {Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh30};

bool has_zero_component(const Ray& ray) { return ray.dir.x == 0.0f || ray.dir.y == 0.0f || ray.dir.z == 0.0f; }

// Random rays (accel_test_rays.h), grazing rays at the nodes of the tree,
// and rays from inside the scene with zero components.
std::vector<Ray> scene_rays(const SceneGeometry& g, const CwbvhBvh& cw, uint32_t seed) {
    std::vector<Ray> rays = test::make_rays(g, 1500, seed);
    std::mt19937 rng(seed);
    for (size_t i = 0; i < cw.nodes.size(); i += std::max<size_t>(1, cw.nodes.size() / 40)) {
        const std::vector<Ray> grazing = grazing_rays(cw.nodes[i], rng);
        rays.insert(rays.end(), grazing.begin(), grazing.end());
    }
    return rays;
}

// Closest hits of the two traversals (bit-exact: same t always, same u, v
// where the primitive is the same; the primitive may differ only on an exact
// tie, where t may differ in the sign of a zero) and against brute force;
// any-hit flags the same.
void expect_same_closest(const Hit& got, const Hit& expected, const Ray& ray, const char* what) {
    ASSERT_EQ(got.found(), expected.found()) << what;
    if (!expected.found()) return;
    EXPECT_EQ(got.t, expected.t) << what;  // (+0 and -0 from two triangles tied at the origin)
    if (got.prim == expected.prim) {
        EXPECT_EQ(bits(got.t), bits(expected.t)) << what;
        EXPECT_EQ(bits(got.u), bits(expected.u)) << what;
        EXPECT_EQ(bits(got.v), bits(expected.v)) << what;
    }
    EXPECT_GE(got.t, ray.tmin);
    EXPECT_LE(got.t, ray.tmax);
}

TEST(CwbvhFma, HitsEqualTheSlabTestTraversalAndBruteForce) {
    size_t rays_traced = 0, old_misses_total = 0;
    for (const NamedScene& scene : test_scenes()) {
        const BruteForceAccel brute(scene.g);
        for (Builder builder : kBuilders) {
            SCOPED_TRACE(scene.name + " / " + to_string(builder));
            const Bvh bvh = build_bvh(scene.g.triangles, BuildOptions{.builder = builder});
            const CwbvhBvh cw = build_cwbvh(bvh, scene.g.triangles);
            const CwbvhView view = cw.view();
            size_t hits = 0, ties = 0, old_misses = 0;
            for (const Ray& ray : scene_rays(scene.g, cw, 17)) {
                const Hit expected = brute.intersect(ray);
                const Hit old = cwbvh_intersect(view, ray);
                const Hit got = cwbvh_fma_intersect(view, ray);
                expect_same_closest(got, expected, ray, "brute force");
                // The slab-test traversal can miss a closer hit that brute
                // force finds (see old_misses): compare with it where it agrees.
                if (old.found() == expected.found() && old.t == expected.t) {
                    expect_same_closest(got, old, ray, "cwbvh");
                    ties += got.prim != old.prim;
                } else {
                    ++old_misses;
                }
                EXPECT_EQ(cwbvh_fma_occluded(view, ray), expected.found());
                // Postponing every triangle group it may (the device policy's extreme).
                AlwaysPostpone always;
                expect_same_closest(cwbvh_fma_intersect(view, ray, always), expected, ray, "postponing");
                EXPECT_EQ(cwbvh_fma_occluded(view, ray, always), expected.found());
                TraversalCounters counters;
                const Hit counted = cwbvh_fma_intersect_counted(view, ray, counters);
                EXPECT_EQ(counted.prim, got.prim);
                EXPECT_EQ(bits(counted.t), bits(got.t));
                EXPECT_EQ(cwbvh_fma_occluded_counted(view, ray, counters), expected.found());
                hits += expected.found();
                ++rays_traced;
                if (::testing::Test::HasFailure()) return;
            }
            EXPECT_GT(hits, 100u);
            EXPECT_LT(ties, hits / 50 + 2);
            old_misses_total += old_misses;
            if (old_misses != 0)
                std::printf("%s / %s: the slab-test cwbvh traversal differs from brute force on %zu rays "
                            "(cwbvh-fma does not)\n",
                            scene.name.c_str(), to_string(builder).c_str(), old_misses);
        }
    }
    std::printf("%zu rays; the slab-test cwbvh traversal differs from brute force on %zu of them\n", rays_traced,
                old_misses_total);
}

TEST(CwbvhFma, AxisParallelRaysAlongBoxFaces) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const Bvh bvh = build_bvh(cube.triangles, BuildOptions{.max_leaf_size = 1});
    const CwbvhBvh cw = build_cwbvh(bvh, cube.triangles);
    const BruteForceAccel brute(cube);
    int hits = 0;
    for (int i = -6; i <= 6; ++i) {
        for (int j = -6; j <= 6; ++j) {
            const float a = static_cast<float>(i) / 3.0f, b = static_cast<float>(j) / 3.0f;
            for (const Ray& ray : {Ray{Vec3f(a, b, -5.0f), 0.0f, Vec3f(0, 0, 1)},
                                   Ray{Vec3f(5.0f, a, b), 0.0f, Vec3f(-1, 0, 0)},
                                   Ray{Vec3f(a, -5.0f, b), 0.0f, Vec3f(0, 2, 0)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(0, 0, -1)},
                                   Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(-0.0f, 0.0f, 1)},
                                   Ray{Vec3f(a, b, 1.0f), 0.0f, Vec3f(1, 0, 0)},
                                   Ray{Vec3f(1.0f, b, -1.0f), 0.0f, Vec3f(0, 0, 1)}}) {
                const Hit expected = brute.intersect(ray);
                expect_same_closest(cwbvh_fma_intersect(cw.view(), ray), expected, ray, "brute force");
                expect_same_closest(cwbvh_fma_intersect(cw.view(), ray), cwbvh_intersect(cw.view(), ray), ray,
                                    "cwbvh");
                EXPECT_EQ(cwbvh_fma_occluded(cw.view(), ray), expected.found());
                hits += expected.found();
            }
        }
    }
    EXPECT_GT(hits, 100);
}

TEST(CwbvhFma, EmptyAndSingleTriangle) {
    const Ray ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1)};
    EXPECT_FALSE(cwbvh_fma_intersect(CwbvhView{}, ray).found());
    EXPECT_FALSE(cwbvh_fma_occluded(CwbvhView{}, ray));
    SceneGeometry g;
    test::append(g, {Vec3f(-1, -1, 0), Vec3f(1, -1, 0), Vec3f(0, 1, 0)});
    const CwbvhBvh cw = build_cwbvh(build_bvh(g.triangles, BuildOptions{}), g.triangles);
    const Hit hit = cwbvh_fma_intersect(cw.view(), ray);
    ASSERT_TRUE(hit.found());
    EXPECT_EQ(hit.t, 2.0f);
    EXPECT_FALSE(cwbvh_fma_intersect(cw.view(), Ray{Vec3f(0, 0, -2), 0.0f, Vec3f(0, 0, 1), 1.5f}).found());
    EXPECT_FALSE(cwbvh_fma_occluded(cw.view(), Ray{Vec3f(5, 5, -2), 0.0f, Vec3f(0, 0, 1)}));
}

TEST(CwbvhFma, PerNodeTestNeverCullsAChildTheRayEnters) {
    CullStats grazing, random, zero;
    for (const NamedScene& scene : test_scenes()) {
        SCOPED_TRACE(scene.name);
        const CullStats random_before = random;
        const Bvh bvh = build_bvh(scene.g.triangles, BuildOptions{.builder = Builder::Sbvh});
        const CwbvhBvh cw = build_cwbvh(bvh, scene.g.triangles);
        std::mt19937 rng(99);
        const std::vector<Ray> random_rays = test::make_rays(scene.g, 200, 31);
        for (uint32_t index = 0; index < cw.nodes.size(); ++index) {
            for (const Ray& ray : grazing_rays(cw.nodes[index], rng)) check_node_never_culls(cw, index, ray, grazing);
            for (size_t i = index % 7; i < random_rays.size(); i += 7)
                check_node_never_culls(cw, index, random_rays[i], has_zero_component(random_rays[i]) ? zero : random);
            if (::testing::Test::HasFailure()) return;
        }
        const size_t missed = random.missed - random_before.missed;
        const size_t extra = random.extra_accepts - random_before.extra_accepts;
        std::printf("per-node test on %s, random rays: %zu of %zu missed slots accepted\n", scene.name.c_str(), extra,
                    missed);
        // Where the ray's origin is far from the scene relative to its size
        // (far, tiny), the pad's |org * idir| term is large against the boxes.
        if (scene.name != "far" && scene.name != "tiny") EXPECT_LT(double(extra), 0.01 * double(missed));
    }
    EXPECT_GT(grazing.entered, 10000u);
    EXPECT_GT(random.missed, 10000u);
    EXPECT_GT(zero.missed, 1000u);
    // The pad costs little: few children the exact test says are missed are
    // accepted, on random rays with and without zero components (grazing
    // rays are near misses by construction: there the pad shows most).
    EXPECT_LT(double(zero.extra_accepts), 0.01 * double(zero.missed));
    for (const auto& [name, stats] : {std::pair{"grazing", grazing}, std::pair{"random", random},
                                      std::pair{"zero-component", zero}})
        std::printf("per-node test, %s rays: %zu slots entered (all accepted), %zu missed, of which accepted: %zu "
                    "(%.3f %%)\n",
                    name, stats.entered, stats.missed, stats.extra_accepts,
                    100.0 * double(stats.extra_accepts) / double(std::max<size_t>(1, stats.missed)));
}

TEST(CwbvhFma, FourAtATimeMaskArithmeticEqualsThePerChildRule) {
    std::mt19937 rng(5);
    std::uniform_int_distribution<uint32_t> byte(0, 255);
    for (uint32_t oct_inv = 0; oct_inv < 8; ++oct_inv) {
        for (uint32_t meta = 0; meta < 256; ++meta) {
            for (int position = 0; position < 4; ++position) {
                uint32_t others[4] = {byte(rng), byte(rng), byte(rng), byte(rng)};
                others[position] = meta;
                const uint32_t meta4 = others[0] | others[1] << 8 | others[2] << 16 | others[3] << 24;
                const detail::CwbvhChildBits4 four = detail::cwbvh_child_bits4(meta4, oct_inv * 0x01010101u);
                for (int k = 0; k < 4; ++k) {
                    const uint32_t m = others[k];
                    const uint32_t index = cwbvh_meta_is_inner(uint8_t(m)) ? (m ^ oct_inv) & 31u : m & 31u;
                    ASSERT_EQ(detail::cwbvh_byte(four.bit_index4, k), index) << meta << ' ' << oct_inv << ' ' << k;
                    ASSERT_EQ(detail::cwbvh_byte(four.child_bits4, k), m >> 5) << meta << ' ' << oct_inv << ' ' << k;
                }
            }
        }
    }
}

TEST(CwbvhFma, NodeWordsHoldTheNodeFields) {
    const SceneGeometry g = test::make_triangle_soup(800, 3, {Vec3f(-3.0f), Vec3f(3.0f)}, 0.3f);
    const CwbvhBvh cw = build_cwbvh(build_bvh(g.triangles, BuildOptions{}), g.triangles);
    for (uint32_t i = 0; i < cw.nodes.size(); ++i) {
        const CwbvhNode& n = cw.nodes[i];
        const detail::CwbvhNodeWords w = detail::cwbvh_load_node_words(cw.nodes.data(), i);
        EXPECT_EQ(w.w[0].x, bits(n.p[0]));
        EXPECT_EQ(w.w[0].z, bits(n.p[2]));
        EXPECT_EQ(w.w[0].w, n.e[0] | n.e[1] << 8 | n.e[2] << 16 | uint32_t(n.imask) << 24);
        EXPECT_EQ(w.w[1].x, n.base_index_child);
        EXPECT_EQ(w.w[1].y, n.base_index_triangle);
        for (int k = 0; k < 4; ++k) {
            EXPECT_EQ(detail::cwbvh_byte(w.w[1].z, k), n.meta[k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[1].w, k), n.meta[4 + k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[2].y, k), n.q_lo_x[4 + k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[2].z, k), n.q_lo_y[k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[3].x, k), n.q_lo_z[k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[3].w, k), n.q_hi_x[4 + k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[4].x, k), n.q_hi_y[k]);
            EXPECT_EQ(detail::cwbvh_byte(w.w[4].w, k), n.q_hi_z[4 + k]);
        }
        // The grid steps from the packed exponents.
        for (int a = 0; a < 3; ++a) {
            const uint32_t step_bits = (w.w[0].w << (23 - 8 * a)) & 0x7F800000u;
            float step;
            std::memcpy(&step, &step_bits, sizeof step);
            EXPECT_EQ(step, cwbvh_step(n.e[a]));
        }
    }
}

// Node fetches: the same nodes as the slab-test traversal, up to the pad
// (a few more) and the slab test's own slack (possibly fewer).
TEST(CwbvhFma, FetchesTheNodesOfTheSlabTestTraversal) {
    uint64_t totals[2][2] = {{0, 0}, {0, 0}};  // [zero component][slab test, fma]
    size_t equal = 0, rays_counted = 0;
    for (const NamedScene& scene : test_scenes()) {
        SCOPED_TRACE(scene.name);
        const CwbvhBvh cw = build_cwbvh(build_bvh(scene.g.triangles, BuildOptions{}), scene.g.triangles);
        const CwbvhView view = cw.view();
        uint64_t scene_old = 0, scene_fma = 0;
        for (const Ray& ray : test::make_rays(scene.g, 2000, 9)) {
            CwbvhCounters old_counts, fma_counts;
            const Hit old_hit = cwbvh_intersect_counted(view, ray, old_counts);
            const Hit fma_hit = cwbvh_fma_intersect_counted(view, ray, fma_counts);
            ASSERT_EQ(old_hit.t, fma_hit.t);
            // TraversalCounters: node fetches as nodes_visited.
            TraversalCounters traversal;
            cwbvh_fma_intersect_counted(view, ray, traversal);
            EXPECT_EQ(traversal.nodes_visited, fma_counts.nodes_visited);
            EXPECT_EQ(traversal.prims_tested, fma_counts.prims_tested);
            EXPECT_EQ(traversal.node_fetches, fma_counts.nodes_visited);
            // The slab-test traversal's TraversalCounters: the same fetches in node_fetches.
            TraversalCounters old_traversal;
            cwbvh_intersect_counted(view, ray, old_traversal);
            EXPECT_EQ(old_traversal.node_fetches, old_counts.nodes_visited);
            const int zero = has_zero_component(ray) ? 1 : 0;
            totals[zero][0] += old_counts.nodes_visited;
            totals[zero][1] += fma_counts.nodes_visited;
            scene_old += old_counts.nodes_visited;
            scene_fma += fma_counts.nodes_visited;
            ++rays_counted;
            equal += old_counts.nodes_visited == fma_counts.nodes_visited;
        }
        std::printf("node fetches on %s: slab test %llu, per-node fma %llu\n", scene.name.c_str(),
                    (unsigned long long)scene_old, (unsigned long long)scene_fma);
    }
    std::printf("node fetches: slab test %llu, per-node fma %llu (rays without zero components), %llu, %llu (with); "
                "%zu of %zu rays equal\n",
                (unsigned long long)totals[0][0], (unsigned long long)totals[0][1],
                (unsigned long long)totals[1][0], (unsigned long long)totals[1][1], equal, rays_counted);
    EXPECT_GE(double(equal), 0.9 * double(rays_counted));
    for (int zero = 0; zero < 2; ++zero) {
        EXPECT_LE(double(totals[zero][1]), 1.02 * double(totals[zero][0]));
        EXPECT_GE(double(totals[zero][1]), 0.98 * double(totals[zero][0]));
    }
}

}  // namespace
}  // namespace rf
