// The SAH kd-tree of Zlatuška 2009 (Wald and Havran 2006 build; stack, short-stack,
// restart and pushdown traversals): every traversal with and without perfect
// splits against brute force, structural invariants of the built tree,
// determinism across thread counts, SAH against a median-split tree, and
// termination of the restart traversals on zero-thickness cells.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/kdtree/kdtree.h"
#include "accel/kdtree/kdtree_accel.h"
#include "accel/kdtree/kdtree_build.h"
#include "accel/kdtree/polygon_clip.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"
#include "trace/kdtree_traversal.h"

namespace rf {
namespace {

constexpr KdTraversal kTraversals[] = {KdTraversal::Stack, KdTraversal::ShortStack, KdTraversal::Restart,
                                       KdTraversal::Pushdown};

// The ray mix of the BVH traversal tests: random origins around and inside the
// scene, rays aimed at triangles and at vertices, axis-parallel directions
// (zero components), and [tmin, tmax] limits.
using test::make_rays;

// build_kdtree with the default SAH costs and bins.
KdTree build_kdtree_with(std::span<const Triangle> triangles, bool perfect_splits) {
    return build_kdtree(triangles, SahCosts{}, BinnedSahOptions{}, KdTreeOptions{.perfect_splits = perfect_splits});
}

// Axis-parallel rays from outside through an axis-aligned lattice, with
// origins exactly on the lattice planes (rays lying in split planes).
std::vector<Ray> make_lattice_rays(const Box3f& box, int steps) {
    std::vector<Ray> rays;
    const Vec3f e = box.extent();
    for (int i = 0; i <= steps; ++i) {
        for (int j = 0; j <= steps; ++j) {
            const float a = static_cast<float>(i) / static_cast<float>(steps);
            const float b = static_cast<float>(j) / static_cast<float>(steps);
            for (int axis = 0; axis < 3; ++axis) {
                const int u = (axis + 1) % 3, v = (axis + 2) % 3;
                for (float sign : {1.0f, -1.0f}) {
                    Ray ray;
                    ray.org[u] = box.lo[u] + a * e[u];
                    ray.org[v] = box.lo[v] + b * e[v];
                    ray.org[axis] = sign > 0.0f ? box.lo[axis] - e[axis] : box.hi[axis] + e[axis];
                    ray.dir = Vec3f(0.0f);
                    ray.dir[axis] = sign;
                    rays.push_back(ray);
                    // The same line from the scene's middle (starting inside).
                    ray.org[axis] = box.lo[axis] + 0.5f * e[axis];
                    rays.push_back(ray);
                }
            }
        }
    }
    return rays;
}

std::unique_ptr<Accel> make_accel(const SceneGeometry& g, const KdTree& tree, KdTraversal traversal,
                                        int short_stack = 4) {
    return make_kdtree_accel(g, tree, traversal, short_stack, 0.0);
}

void expect_same_closest(const Hit& got, const Hit& brute, const Ray& ray, const std::string& what) {
    ASSERT_EQ(got.found(), brute.found()) << what << " org " << ray.org.x << " " << ray.org.y << " " << ray.org.z
                                          << " dir " << ray.dir.x << " " << ray.dir.y << " " << ray.dir.z;
    if (!brute.found()) return;
    if (got.prim != brute.prim) {
        // Another triangle only at (almost) the same distance: a tie.
        EXPECT_NEAR(got.t, brute.t, 1e-5f * std::fabs(brute.t)) << what << " prim " << got.prim << " brute prim "
                                                                  << brute.prim;
    } else {
        EXPECT_NEAR(got.t, brute.t, 1e-5f * std::fabs(brute.t)) << what;
    }
    EXPECT_GE(got.t, ray.tmin);
    EXPECT_LE(got.t, ray.tmax);
}

// Every traversal, with and without perfect splits, against brute force. All
// four traversals visit the same leaves in the same order, so their answers
// must agree exactly with each other.
void compare_with_brute_force(const SceneGeometry& g, const std::vector<Ray>& rays, const std::string& scene,
                              bool expect_some_misses = true) {
    const BruteForceAccel brute(g);
    std::vector<Hit> expected(rays.size());
    for (size_t i = 0; i < rays.size(); ++i) expected[i] = brute.intersect(rays[i]);
    size_t hits = 0;
    for (const Hit& h : expected) hits += h.found();
    EXPECT_GT(hits, rays.size() / 10) << scene;
    if (expect_some_misses) EXPECT_LT(hits, rays.size()) << scene;

    for (bool perfect : {true, false}) {
        const KdTree tree = build_kdtree_with(g.triangles, perfect);
        std::vector<Hit> reference;
        for (KdTraversal traversal : kTraversals) {
            const std::string what = scene + " " + to_string(traversal) + (perfect ? " perfect" : " bounds");
            const auto kd = make_accel(g, tree, traversal, traversal == KdTraversal::ShortStack ? 2 : 4);
            std::vector<Hit> got(rays.size());
            for (size_t i = 0; i < rays.size(); ++i) {
                got[i] = kd->intersect(rays[i]);
                expect_same_closest(got[i], expected[i], rays[i], what + " ray " + std::to_string(i));
                ASSERT_EQ(kd->occluded(rays[i]), expected[i].found()) << what << " ray " << i;
                if (::testing::Test::HasFatalFailure()) return;
            }
            if (reference.empty()) {
                reference = got;
                continue;
            }
            for (size_t i = 0; i < rays.size(); ++i) {
                EXPECT_EQ(got[i].prim, reference[i].prim) << what << " ray " << i;
                EXPECT_EQ(got[i].t, reference[i].t) << what << " ray " << i;
            }
        }
    }
}

TEST(KdTreeTraversal, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 31, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    compare_with_brute_force(soup, make_rays(soup, 1500, 1), "soup");
}

TEST(KdTreeTraversal, MatchesBruteForceOnIcosphere) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    compare_with_brute_force(sphere, make_rays(sphere, 2000, 2), "icosphere");
}

TEST(KdTreeTraversal, MatchesBruteForceOnTessellatedCube) {
    // Axis-aligned flat triangles everywhere: planar events, flat cells, rays
    // along cell faces and in split planes.
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    std::vector<Ray> rays = make_rays(cube, 2000, 3);
    const std::vector<Ray> lattice = make_lattice_rays(cube.bounds, 8);
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    compare_with_brute_force(cube, rays, "cube");
}

TEST(KdTreeTraversal, MatchesBruteForceOnDegenerateAndThinTriangles) {
    const SceneGeometry nasty = test::make_nasty_geometry(5);
    std::vector<Ray> rays = make_rays(nasty, 2500, 4);
    const std::vector<Ray> lattice = make_lattice_rays(Box3f{Vec3f(-4.0f), Vec3f(4.0f)}, 8);
    rays.insert(rays.end(), lattice.begin(), lattice.end());
    compare_with_brute_force(nasty, rays, "nasty");
}

TEST(KdTreeTraversal, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(1500, 32, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    compare_with_brute_force(far, make_rays(far, 1500, 5), "far");
    const SceneGeometry huge = test::make_triangle_soup(1500, 33, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    compare_with_brute_force(huge, make_rays(huge, 1500, 6), "huge");
}

TEST(KdTreeTraversal, ShortStackOfEverySizeMatchesStack) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(3), 2.0f);
    const KdTree tree = build_kdtree_with(sphere.triangles, true);  // perfect splits: the default
    const auto stack = make_accel(sphere, tree, KdTraversal::Stack);
    const std::vector<Ray> rays = make_rays(sphere, 500, 7);
    for (int size : {1, 3, 4, 16, 64}) {
        const auto short_stack = make_accel(sphere, tree, KdTraversal::ShortStack, size);
        for (const Ray& ray : rays) {
            const Hit a = stack->intersect(ray), b = short_stack->intersect(ray);
            EXPECT_EQ(a.prim, b.prim) << "stack size " << size;
            EXPECT_EQ(a.t, b.t) << "stack size " << size;
        }
    }
}

// Planes of coplanar triangles, duplicated, plus triangles standing on them:
// perfect splits and planar events make zero-thickness cells here.
SceneGeometry make_flat_cell_scene() {
    SceneGeometry g;
    for (float z : {0.0f, 0.0f, 0.5f, 1.0f}) {
        for (int i = 0; i < 4; ++i) {
            for (int j = 0; j < 4; ++j) {
                const float x = static_cast<float>(i) * 0.5f, y = static_cast<float>(j) * 0.5f;
                test::append(g, {Vec3f(x, y, z), Vec3f(x + 0.5f, y, z), Vec3f(x + 0.5f, y + 0.5f, z)});
                test::append(g, {Vec3f(x, y, z), Vec3f(x + 0.5f, y + 0.5f, z), Vec3f(x, y + 0.5f, z)});
            }
        }
    }
    for (int i = 0; i <= 4; ++i) {  // walls in the planes x = 0, 0.5, ... between the floors
        const float x = static_cast<float>(i) * 0.5f;
        test::append(g, {Vec3f(x, 0.0f, 0.0f), Vec3f(x, 2.0f, 0.0f), Vec3f(x, 2.0f, 1.0f)});
        test::append(g, {Vec3f(x, 0.0f, 0.0f), Vec3f(x, 2.0f, 1.0f), Vec3f(x, 0.0f, 1.0f)});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

TEST(KdTreeTraversal, RestartTerminatesOnFlatCells) {
    const SceneGeometry g = make_flat_cell_scene();
    std::vector<Ray> rays = make_lattice_rays(g.bounds, 8);
    const std::vector<Ray> mixed = make_rays(g, 1000, 8);
    rays.insert(rays.end(), mixed.begin(), mixed.end());
    for (bool perfect : {true, false}) {
        const KdTree tree = build_kdtree_with(g.triangles, perfect);
        // The scene must really produce zero-thickness leaves.
        size_t flat = 0;
        for (const KdLeafInfo& leaf : tree.leaves()) {
            const Vec3f e = leaf.cell.extent();
            flat += (e.x == 0.0f || e.y == 0.0f || e.z == 0.0f) && tree.nodes[leaf.node].prim_count() > 0;
        }
        EXPECT_GT(flat, 0u) << "perfect " << perfect;
        for (KdTraversal traversal : {KdTraversal::Restart, KdTraversal::Pushdown, KdTraversal::ShortStack}) {
            const KdTreeView view{tree.nodes.data(), tree.prim_indices.data(), g.triangles.data(),
                                  uint32_t(tree.nodes.size()), tree.bounds, 1};
            for (const Ray& ray : rays) {
                // Each leaf is visited at most once per ray, each after at
                // most one descent: a loop would break these bounds.
                KdTraversalCounters counters;
                if (traversal == KdTraversal::Restart) (void)kdtree_intersect_counted<KdTraversal::Restart>(view, ray, counters);
                else if (traversal == KdTraversal::Pushdown) (void)kdtree_intersect_counted<KdTraversal::Pushdown>(view, ray, counters);
                else (void)kdtree_intersect_counted<KdTraversal::ShortStack>(view, ray, counters);
                EXPECT_LE(counters.restarts, tree.leaf_count());
                EXPECT_LE(counters.nodes_visited, tree.leaf_count() * static_cast<size_t>(tree.max_depth + 1));
            }
        }
    }
    compare_with_brute_force(g, rays, "flat cells", false);
}

// ---------------------------------------------------------------- build ---

// Separating-axis test of a triangle against a box (Akenine-Moeller 2001), in
// double; `shrink` > 0 tests against the box's interior shrunk by that much.
bool triangle_overlaps_box(const Triangle& tri, const Box3f& box, double shrink) {
    double c[3], h[3], v[3][3];
    for (int k = 0; k < 3; ++k) {
        c[k] = 0.5 * (static_cast<double>(box.lo[k]) + box.hi[k]);
        h[k] = 0.5 * (static_cast<double>(box.hi[k]) - box.lo[k]) - shrink;
        if (h[k] < 0.0) return false;
        v[0][k] = tri.v0[k] - c[k];
        v[1][k] = tri.v1[k] - c[k];
        v[2][k] = tri.v2[k] - c[k];
    }
    auto separated = [&](const double a[3]) {
        double lo = INFINITY, hi = -INFINITY;
        for (const auto& p : v) {
            const double d = a[0] * p[0] + a[1] * p[1] + a[2] * p[2];
            lo = std::min(lo, d);
            hi = std::max(hi, d);
        }
        const double r = h[0] * std::fabs(a[0]) + h[1] * std::fabs(a[1]) + h[2] * std::fabs(a[2]);
        return shrink > 0.0 ? (lo >= r || hi <= -r) : (lo > r || hi < -r);
    };
    double e[3][3];
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) e[i][k] = v[(i + 1) % 3][k] - v[i][k];
    for (int axis = 0; axis < 3; ++axis) {
        const double a[3] = {axis == 0 ? 1.0 : 0.0, axis == 1 ? 1.0 : 0.0, axis == 2 ? 1.0 : 0.0};
        if (separated(a)) return false;
    }
    const double n[3] = {e[0][1] * e[1][2] - e[0][2] * e[1][1], e[0][2] * e[1][0] - e[0][0] * e[1][2],
                         e[0][0] * e[1][1] - e[0][1] * e[1][0]};
    if (separated(n)) return false;
    for (int axis = 0; axis < 3; ++axis) {
        for (const auto& edge : e) {
            const double u[3] = {axis == 0 ? 1.0 : 0.0, axis == 1 ? 1.0 : 0.0, axis == 2 ? 1.0 : 0.0};
            const double a[3] = {u[1] * edge[2] - u[2] * edge[1], u[2] * edge[0] - u[0] * edge[2],
                                 u[0] * edge[1] - u[1] * edge[0]};
            if (a[0] == 0.0 && a[1] == 0.0 && a[2] == 0.0) continue;
            if (separated(a)) return false;
        }
    }
    return true;
}

bool is_degenerate(const Triangle& t) {
    const Vec3f n = cross(t.v1 - t.v0, t.v2 - t.v0);
    return n.x == 0.0f && n.y == 0.0f && n.z == 0.0f;
}

void check_structure(const SceneGeometry& g, bool perfect, const std::string& scene) {
    const KdTree tree = build_kdtree_with(g.triangles, perfect);
    const std::string what = scene + (perfect ? " perfect" : " bounds");
    size_t usable = 0;
    for (const Triangle& t : g.triangles) usable += !is_degenerate(t);
    ASSERT_FALSE(tree.nodes.empty()) << what;
    EXPECT_EQ(tree.max_depth, kdtree_max_depth(usable)) << what;
    EXPECT_LE(tree.depth(), tree.max_depth) << what;
    EXPECT_LE(tree.max_depth, kKdMaxDepth) << what;
    EXPECT_TRUE(g.bounds.contains(tree.bounds)) << what;

    const std::vector<KdLeafInfo> leaves = tree.leaves();
    EXPECT_EQ(leaves.size(), tree.leaf_count()) << what;
    EXPECT_EQ(tree.nodes.size(), 2 * leaves.size() - 1) << what;
    std::vector<char> referenced(g.triangles.size(), 0);
    const double tolerance = 1e-5 * std::max(1.0, static_cast<double>(max_component(abs(tree.bounds.hi)) +
                                                                      max_component(abs(tree.bounds.lo))));
    for (const KdLeafInfo& leaf : leaves) {
        // Leaf cells are proper boxes inside the root cell.
        ASSERT_FALSE(leaf.cell.is_empty()) << what;
        EXPECT_TRUE(tree.bounds.contains(leaf.cell)) << what;
        const KdNode& node = tree.nodes[leaf.node];
        std::vector<char> in_leaf(g.triangles.size(), 0);
        for (uint32_t s = node.prim_offset(); s < node.prim_offset() + node.prim_count(); ++s) {
            const uint32_t prim = tree.prim_indices[s];
            ASSERT_LT(prim, g.triangles.size());
            EXPECT_FALSE(in_leaf[prim]) << what << ": triangle twice in one leaf";
            in_leaf[prim] = 1;
            referenced[prim] = 1;
            // A referenced triangle touches the (slightly grown) cell.
            Box3f grown = leaf.cell;
            grown.lo = grown.lo - Vec3f(static_cast<float>(tolerance));
            grown.hi = grown.hi + Vec3f(static_cast<float>(tolerance));
            if (perfect) {
                EXPECT_TRUE(triangle_overlaps_box(g.triangles[prim], grown, 0.0)) << what << ": prim " << prim;
            } else {
                const Box3f b = g.triangles[prim].bounds();
                const Box3f overlap{max(b.lo, grown.lo), min(b.hi, grown.hi)};
                EXPECT_FALSE(overlap.is_empty()) << what << ": prim " << prim;
            }
        }
        // Every triangle reaching into the cell's interior is in the leaf.
        for (size_t prim = 0; prim < g.triangles.size(); ++prim) {
            if (in_leaf[prim] || is_degenerate(g.triangles[prim])) continue;
            EXPECT_FALSE(triangle_overlaps_box(g.triangles[prim], leaf.cell, tolerance))
                << what << ": triangle " << prim << " overlaps leaf " << leaf.node << " but is not in it";
        }
    }
    for (size_t prim = 0; prim < g.triangles.size(); ++prim) {
        EXPECT_EQ(static_cast<bool>(referenced[prim]), !is_degenerate(g.triangles[prim])) << what << " " << prim;
    }
}

TEST(KdTreeBuild, StructuralInvariants) {
    const SceneGeometry soup = test::make_triangle_soup(600, 34, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.8f);
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(4));
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(2));
    const SceneGeometry nasty = test::make_nasty_geometry(6);
    for (bool perfect : {true, false}) {
        check_structure(soup, perfect, "soup");
        check_structure(cube, perfect, "cube");
        check_structure(sphere, perfect, "sphere");
        check_structure(nasty, perfect, "nasty");
        check_structure(make_flat_cell_scene(), perfect, "flat cells");
    }
}

TEST(KdTreeBuild, PolygonClipKeepsOnlyThePartInTheCell) {
    const Triangle tri{Vec3f(0.0f, 0.0f, 0.0f), Vec3f(4.0f, 0.0f, 0.0f), Vec3f(0.0f, 4.0f, 0.0f)};
    Box3f part;
    ASSERT_TRUE(clip_triangle_bounds(tri, Box3f{Vec3f(1.0f, 1.0f, -1.0f), Vec3f(5.0f, 5.0f, 1.0f)}, part));
    EXPECT_EQ(part.lo.x, 1.0f);
    EXPECT_EQ(part.lo.y, 1.0f);
    EXPECT_EQ(part.hi.x, 3.0f);  // the hypotenuse x + y = 4 at y = 1
    EXPECT_EQ(part.hi.y, 3.0f);
    EXPECT_EQ(part.lo.z, 0.0f);
    EXPECT_EQ(part.hi.z, 0.0f);
    // The triangle's box overlaps this cell, the triangle does not.
    EXPECT_FALSE(clip_triangle_bounds(tri, Box3f{Vec3f(3.0f, 3.0f, -1.0f), Vec3f(4.0f, 4.0f, 1.0f)}, part));
}

TEST(KdTreeBuild, DeterministicAcrossThreadCounts) {
    // Big enough for binned levels and subtrees built as parallel tasks.
    const SceneGeometry soup = test::make_triangle_soup(12000, 35, {Vec3f(-20.0f), Vec3f(20.0f)}, 0.6f);
    for (bool perfect : {true, false}) {
        const KdTree one = parallel::with_threads(1, [&] { return build_kdtree_with(soup.triangles, perfect); });
        for (int threads : {2, 3}) {
            const KdTree many =
                parallel::with_threads(threads, [&] { return build_kdtree_with(soup.triangles, perfect); });
            ASSERT_EQ(one.nodes.size(), many.nodes.size()) << threads;
            for (size_t i = 0; i < one.nodes.size(); ++i) {
                ASSERT_EQ(one.nodes[i].word0, many.nodes[i].word0) << i;
                ASSERT_EQ(one.nodes[i].word1, many.nodes[i].word1) << i;
            }
            EXPECT_EQ(one.prim_indices, many.prim_indices) << threads;
        }
    }
}

// A naive kd-tree: spatial median of the longest axis, triangles by bounds,
// leaves of at most 4 triangles or at the depth limit.
struct MedianBuilder {
    const SceneGeometry& g;
    KdTree tree;
    void build(std::vector<uint32_t> prims, const Box3f& cell, int depth, size_t slot) {
        const int axis = cell.largest_axis();
        if (prims.size() <= 4 || depth >= tree.max_depth) {
            tree.nodes[slot] = KdNode::leaf(static_cast<uint32_t>(tree.prim_indices.size()),
                                            static_cast<uint32_t>(prims.size()));
            tree.prim_indices.insert(tree.prim_indices.end(), prims.begin(), prims.end());
            return;
        }
        const float split = 0.5f * (cell.lo[axis] + cell.hi[axis]);
        std::vector<uint32_t> below, above;
        for (uint32_t p : prims) {
            const Box3f b = g.triangles[p].bounds();
            if (b.lo[axis] < split || b.hi[axis] <= split) below.push_back(p);
            if (b.hi[axis] > split) above.push_back(p);
        }
        Box3f cb = cell, ca = cell;
        cb.hi[axis] = split;
        ca.lo[axis] = split;
        const size_t first = tree.nodes.size();
        tree.nodes.resize(first + 2);
        tree.nodes[slot] = KdNode::inner(axis, split, static_cast<uint32_t>(first));
        build(std::move(below), cb, depth + 1, first);
        build(std::move(above), ca, depth + 1, first + 1);
    }
};

double median_split_sah(const SceneGeometry& g) {
    MedianBuilder m{g, {}};
    std::vector<uint32_t> prims;
    for (uint32_t i = 0; i < g.triangles.size(); ++i) {
        if (!is_degenerate(g.triangles[i])) {
            prims.push_back(i);
            m.tree.bounds.extend(g.triangles[i].bounds());
        }
    }
    m.tree.max_depth = kdtree_max_depth(prims.size());
    m.tree.nodes.resize(1);
    const Box3f bounds = m.tree.bounds;
    m.build(std::move(prims), bounds, 0, 0);
    return m.tree.sah_cost(1.0f, 1.0f);
}

TEST(KdTreeBuild, SahNotWorseThanMedianSplit) {
    const std::vector<std::pair<std::string, SceneGeometry>> scenes = {
        {"soup", test::make_triangle_soup(5000, 36, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)},
        {"sphere", test::to_geometry(test::make_icosphere(4))},
        {"cube", test::to_geometry(test::make_tessellated_cube(16))},
        {"nasty", test::make_nasty_geometry(7)}};
    for (const auto& [name, g] : scenes) {
        const double median = median_split_sah(g);
        for (bool perfect : {true, false}) {
            const KdTree tree = build_kdtree_with(g.triangles, perfect);
            const double sah = tree.sah_cost(1.0f, 1.0f);
            EXPECT_LE(sah, median) << name << (perfect ? " perfect" : " bounds");
            EXPECT_GT(sah, 0.0) << name;
            std::printf("[ kd-tree  ] %-7s %-8s SAH %8.2f (median split %8.2f), %zu nodes, depth %d of %d\n",
                        name.c_str(), perfect ? "perfect" : "bounds", sah, median, tree.nodes.size(), tree.depth(),
                        tree.max_depth);
        }
    }
}

TEST(KdTreeBuild, PerfectSplitsDoNotHurtSah) {
    // Clipping only removes references that cannot be hit: SAH should not grow
    // by much on long thin triangles (where bounds-only trees suffer most).
    SceneGeometry g;
    std::mt19937 rng(37);
    std::uniform_real_distribution<float> u(-10.0f, 10.0f);
    for (int i = 0; i < 3000; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        const Vec3f d = test::random_direction(rng) * 6.0f;
        test::append(g, {a, a + d, a + d + test::random_direction(rng) * 0.05f});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    const double with = build_kdtree_with(g.triangles, true).sah_cost();
    const double without = build_kdtree_with(g.triangles, false).sah_cost();
    EXPECT_LT(with, without);
}

// ---------------------------------------------------------------- accel ---

TEST(KdTreeAccel, BuildAccelStatsAndCounts) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4));
    const std::vector<Ray> rays = make_rays(sphere, 1000, 9);
    TraversalTotals stack_totals;
    for (KdTraversal traversal : kTraversals) {
        const auto accel =
            build_accel(sphere, BuildOptions{.structure = Structure::KdTree, .kdtree = {.traversal = traversal}});
        const AccelStats s = accel->stats();
        EXPECT_EQ(s.name, "kdtree/sah/" + to_string(traversal));
        EXPECT_GT(s.node_count, 1u);
        EXPECT_EQ(s.node_count, 2 * s.leaf_count - 1);
        EXPECT_GE(s.bytes, s.node_count * 8);
        EXPECT_GT(s.sah_cost, 1.0);
        EXPECT_TRUE(std::isnan(s.quality_cost));
        EXPECT_GE(s.build_ms, 0.0);
        TraversalTotals totals;
        ASSERT_TRUE(accel->count_traversal(rays, false, totals));
        EXPECT_EQ(totals.rays, rays.size());
        EXPECT_GE(totals.steps, rays.size() / 2);
        EXPECT_GT(totals.prim_tests, 0u);
        EXPECT_LT(totals.prim_tests, rays.size() * sphere.size() / 20);
        if (traversal == KdTraversal::Stack) {
            EXPECT_EQ(totals.restarts, 0u);
            stack_totals = totals;
        } else {
            // Same leaves, same triangle tests; restarts cost extra steps.
            EXPECT_EQ(totals.prim_tests, stack_totals.prim_tests) << to_string(traversal);
            EXPECT_GE(totals.steps, stack_totals.steps) << to_string(traversal);
            if (traversal != KdTraversal::ShortStack) EXPECT_GT(totals.restarts, 0u) << to_string(traversal);
        }
        TraversalTotals any;
        ASSERT_TRUE(accel->count_traversal(rays, true, any));
        EXPECT_LE(any.prim_tests, totals.prim_tests);
    }
}

TEST(KdTreeAccel, BatchesEqualSingleRays) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 38, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    const std::vector<Ray> rays = make_rays(soup, 2000, 10);
    for (KdTraversal traversal : kTraversals) {
        const auto accel =
            build_accel(soup, BuildOptions{.structure = Structure::KdTree, .kdtree = {.traversal = traversal}});
        std::vector<Hit> hits(rays.size());
        std::vector<uint8_t> occluded(rays.size(), 7);
        accel->intersect(rays, hits);
        accel->occluded(rays, occluded);
        for (size_t i = 0; i < rays.size(); ++i) {
            const Hit single = accel->intersect(rays[i]);
            EXPECT_EQ(hits[i].prim, single.prim);
            EXPECT_EQ(hits[i].t, single.t);
            EXPECT_EQ(occluded[i], accel->occluded(rays[i]) ? 1 : 0);
        }
        std::vector<Hit> too_few(rays.size() - 1);
        EXPECT_THROW(accel->intersect(rays, too_few), Error);
        std::vector<uint8_t> too_many(rays.size() + 1);
        EXPECT_THROW(accel->occluded(rays, too_many), Error);
    }
}

TEST(KdTreeAccel, EmptyAndDegenerateScenesAlwaysMiss) {
    const SceneGeometry empty;
    SceneGeometry points;
    test::append(points, {Vec3f(1.0f), Vec3f(1.0f), Vec3f(1.0f)});
    points.normal_matrices.push_back(Affine3f::identity());
    const SceneGeometry* scenes[] = {&empty, &points};
    for (const SceneGeometry* g : scenes) {
        for (KdTraversal traversal : kTraversals) {
            const auto accel =
                build_accel(*g, BuildOptions{.structure = Structure::KdTree, .kdtree = {.traversal = traversal}});
            const Ray ray{Vec3f(1.0f, 1.0f, -5.0f), 0.0f, Vec3f(0, 0, 1)};
            EXPECT_FALSE(accel->intersect(ray).found());
            EXPECT_FALSE(accel->occluded(ray));
            EXPECT_EQ(accel->stats().node_count, 0u);
        }
    }
}

TEST(KdTreeAccel, MatchesBruteForceOnStanfordBunny) {
    const std::string path = test::shared_path("scenes/stanford-bunny/bun_zipper.ply");
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    Scene scene;
    try {
        scene = load_scene(path);
    } catch (const Error& e) {
        GTEST_SKIP() << "bunny not loadable: " << e.what();
    }
    const SceneGeometry g = SceneGeometry::build(scene);
    const auto kd = build_accel(g, BuildOptions{.structure = Structure::KdTree});
    const BruteForceAccel brute(g);
    for (const Ray& ray : make_rays(g, 100, 11)) {
        const Hit expected = brute.intersect(ray);
        expect_same_closest(kd->intersect(ray), expected, ray, "bunny");
        EXPECT_EQ(kd->occluded(ray), expected.found());
    }
    const AccelStats s = kd->stats();
    std::printf("[ kd-tree  ] bunny: %zu triangles, build %.1f ms, %zu nodes, %zu leaves, SAH %.2f\n", g.size(),
                s.build_ms, s.node_count, s.leaf_count, s.sah_cost);
}

}  // namespace
}  // namespace rf
