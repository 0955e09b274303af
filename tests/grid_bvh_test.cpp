// GridBvh and GridBvhSplit (Garanzha 2014, dissertation ch. 4): the sparse
// grid against brute-force counts, partial triangles (budget, tight clipped
// boxes), structural invariants of the canonical BVH, depth on pathological
// input, determinism across thread counts, traversal against brute force, and
// the SAH gain of partial triangles on long thin triangles.
#include "accel/bvh/builders/grid_bvh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/grid_bvh_partial_triangles.h"
#include "accel/bvh/builders/grid_bvh_sparse_grid.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

using gridbvh::CellBox;
using gridbvh::GridFrame;
using gridbvh::GridRef;
using gridbvh::SparseGrid;

using test::check_bvh;
using test::identical;
using test::Refs;
using test::same_box;
using test::TreeShape;

// GridBvhSplit's partial triangles: in one or more leaves, with clipped boxes.
Refs refs_of(bool split) { return split ? Refs::Partial : Refs::Once; }

SceneGeometry make_geometric_row(int count) {
    SceneGeometry g;
    float x = 1.0f;
    for (int i = 0; i < count; ++i, x *= 1.09f) test::append(g, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    return g;
}

SceneGeometry make_identical(int count) {
    SceneGeometry g;
    for (int i = 0; i < count; ++i) test::append(g, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    return g;
}

// Long thin triangles along the cube's diagonal directions, plus small clutter.
SceneGeometry make_diagonal_slivers(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-10.0f, 10.0f);
    SceneGeometry g;
    for (int i = 0; i < count; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        Vec3f d(1.0f, (i & 1) ? 1.0f : -1.0f, (i & 2) ? 1.0f : -1.0f);
        const Vec3f b = a + d * 6.0f;
        const Vec3f w = test::random_direction(rng) * 0.05f;
        test::append(g, {a, b, a + w});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> test_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(3000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    scenes.push_back({"far", test::make_triangle_soup(2000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    scenes.push_back({"geometric", make_geometric_row(900)});
    scenes.push_back({"identical", make_identical(100)});
    scenes.push_back({"slivers", make_diagonal_slivers(500, 4)});
    scenes.push_back({"cube", test::to_geometry(test::make_tessellated_cube(6))});
    return scenes;
}

// ---------------------------------------------------------------- sparse grid

TEST(GridBvh, SparseGridCountsMatchBruteForce) {
    const SceneGeometry soup = test::make_triangle_soup(20000, 7, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.3f);
    SceneGeometry clustered = test::make_triangle_soup(3000, 8, {Vec3f(0.0f), Vec3f(0.01f)}, 0.001f);
    test::append(clustered, {Vec3f(-50.0f), Vec3f(-50.0f, 1.0f, 0.0f), Vec3f(-50.0f, 0.0f, 1.0f)});
    test::append(clustered, {Vec3f(50.0f), Vec3f(50.0f, 1.0f, 0.0f), Vec3f(50.0f, 0.0f, 1.0f)});
    for (const SceneGeometry* g : std::initializer_list<const SceneGeometry*>{&soup, &clustered}) {
        const std::vector<GridRef> refs = gridbvh::make_triangle_refs(g->triangles);
        Box3f scene;
        for (const GridRef& r : refs) scene.extend(r.bounds());
        const GridFrame frame(scene);
        SparseGrid grid;
        grid.build(refs, frame);
        // Brute force: each reference's Grid0 cell, then its ancestors per level.
        std::vector<std::map<std::tuple<int, int, int>, uint32_t>> expected(gridbvh::kLevels);
        std::map<int, int> tops;
        for (const GridRef& r : refs) {
            const Vec3f c = r.centroid();
            const int x = frame.cell(c.x, 0), y = frame.cell(c.y, 1), z = frame.cell(c.z, 2);
            for (int level = 0; level < gridbvh::kLevels; ++level) ++expected[level][{x >> level, y >> level, z >> level}];
            ++tops[(x >> 3) + 128 * ((y >> 3) + 128 * (z >> 3))];
        }
        EXPECT_EQ(grid.occupied_top_cells(), tops.size());
        std::mt19937 rng(3);
        for (int level = 0; level < gridbvh::kLevels; ++level) {
            SCOPED_TRACE("level " + std::to_string(level));
            for (const auto& [cell, n] : expected[level]) {
                EXPECT_EQ(grid.count(level, std::get<0>(cell), std::get<1>(cell), std::get<2>(cell)), n);
            }
            // Random cells, mostly empty.
            const int res = gridbvh::kFineRes >> level;
            std::uniform_int_distribution<int> pick(0, res - 1);
            for (int i = 0; i < 2000; ++i) {
                const int x = pick(rng), y = pick(rng), z = pick(rng);
                const auto it = expected[level].find({x, y, z});
                EXPECT_EQ(grid.count(level, x, y, z), it == expected[level].end() ? 0u : it->second);
            }
        }
        // for_each_cell over random windows agrees with count().
        std::vector<std::vector<std::tuple<int, int, int>>> cells(gridbvh::kLevels);
        for (int level = 0; level < gridbvh::kLevels; ++level) {
            for (const auto& entry : expected[level]) cells[level].push_back(entry.first);
        }
        for (int level = 0; level < gridbvh::kLevels; ++level) {
            const int res = gridbvh::kFineRes >> level;
            for (int i = 0; i < 200; ++i) {
                // Windows around non-empty cells, up to 8 cells wide.
                const auto& cell = cells[level][std::uniform_int_distribution<size_t>(0, cells[level].size() - 1)(rng)];
                CellBox box;
                const int c[3] = {std::get<0>(cell), std::get<1>(cell), std::get<2>(cell)};
                for (int a = 0; a < 3; ++a) {
                    box.lo[a] = uint16_t(std::max(0, c[a] - int(rng() % 4)));
                    box.hi[a] = uint16_t(std::min(res - 1, int(box.lo[a]) + int(rng() % 8)));
                }
                std::map<std::tuple<int, int, int>, uint32_t> visited;
                grid.for_each_cell(level, box, [&](int x, int y, int z, uint32_t n) { visited[{x, y, z}] += n; });
                for (int z = box.lo[2]; z <= box.hi[2]; ++z) {
                    for (int y = box.lo[1]; y <= box.hi[1]; ++y) {
                        for (int x = box.lo[0]; x <= box.hi[0]; ++x) {
                            const auto v = visited.find({x, y, z});
                            EXPECT_EQ(v == visited.end() ? 0u : v->second, grid.count(level, x, y, z));
                        }
                    }
                }
                EXPECT_LE(visited.size(), size_t(box.extent(0) * box.extent(1) * box.extent(2)));
            }
        }
        // Collecting the whole 8^3 root window yields every reference once.
        std::vector<uint32_t> positions;
        grid.collect(gridbvh::kLevels - 1, CellBox{{0, 0, 0}, {7, 7, 7}}, positions);
        ASSERT_EQ(positions.size(), refs.size());
        std::vector<int> seen(refs.size(), 0);
        for (uint32_t p : positions) ++seen[grid.sorted_refs()[p]];
        EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](int n) { return n == 1; }));
        // Sorted positions group references by Grid0 key.
        for (size_t i = 1; i < refs.size(); ++i) {
            const uint32_t a = gridbvh::fine_key(frame, refs[grid.sorted_refs()[i - 1]].centroid());
            const uint32_t b = gridbvh::fine_key(frame, refs[grid.sorted_refs()[i]].centroid());
            ASSERT_LE(a, b);
        }
    }
}

// ---------------------------------------------------------- partial triangles

TEST(GridBvhSplit, ClippedBoxesAreTightAndInsideTriangleAndRegion) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(-5.0f, 5.0f), unit(0.0f, 1.0f);
    int nonempty = 0, checked_tightness = 0;
    for (int i = 0; i < 1000; ++i) {
        const Triangle tri{Vec3f(u(rng), u(rng), u(rng)), Vec3f(u(rng), u(rng), u(rng)), Vec3f(u(rng), u(rng), u(rng))};
        Box3f region;
        region.extend(Vec3f(u(rng), u(rng), u(rng)));
        region.extend(Vec3f(u(rng), u(rng), u(rng)));
        const Box3f part = gridbvh::clip_triangle_to_box(tri, region);
        if (part.is_empty()) continue;
        ++nonempty;
        EXPECT_TRUE(region.contains(part));
        EXPECT_TRUE(tri.bounds().contains(part));
        if (i % 5 != 0) continue;
        // A dense barycentric grid: triangle points inside the region lie in
        // the part box, and (when there are many) their box nearly fills it.
        Box3f sampled;
        int inside = 0;
        constexpr int kSteps = 160;
        for (int a = 0; a <= kSteps; ++a) {
            for (int b = 0; a + b <= kSteps; ++b) {
                const float b1 = float(a) / kSteps, b2 = float(b) / kSteps;
                const Vec3f p = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
                if (!region.contains(Box3f{p, p})) continue;
                sampled.extend(p);
                ++inside;
            }
        }
        if (inside == 0) continue;
        const Box3f grown{part.lo - Vec3f(1e-5f), part.hi + Vec3f(1e-5f)};
        EXPECT_TRUE(grown.contains(sampled));
        if (inside < 2000) continue;
        ++checked_tightness;
        const Vec3f e = part.extent();
        const float slack = 0.05f * std::max(e.x, std::max(e.y, e.z)) + 1e-4f;
        for (int a = 0; a < 3; ++a) {
            EXPECT_LE(sampled.lo[a] - part.lo[a], slack);
            EXPECT_LE(part.hi[a] - sampled.hi[a], slack);
        }
    }
    EXPECT_GT(checked_tightness, 10);
    EXPECT_GT(nonempty, 100);
    // A box-aligned case, exactly: the triangle (0,0,0) (4,0,0) (0,4,0)
    // between x = 1 and x = 2 spans y in [0, 3].
    const Triangle right{Vec3f(0, 0, 0), Vec3f(4, 0, 0), Vec3f(0, 4, 0)};
    const Box3f slab = gridbvh::clip_triangle_to_box(right, Box3f{Vec3f(1, -10, -10), Vec3f(2, 10, 10)});
    EXPECT_EQ(slab.lo.x, 1.0f);
    EXPECT_EQ(slab.hi.x, 2.0f);
    EXPECT_NEAR(slab.lo.y, 0.0f, 1e-5f);
    EXPECT_NEAR(slab.hi.y, 3.0f, 1e-5f);
}

TEST(GridBvhSplit, PartialTrianglesRespectBudgetAndCoverTriangles) {
    // Big wide triangles among small ones: both passes have work to do.
    SceneGeometry g = test::make_triangle_soup(2000, 5, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f);
    test::append(g, {Vec3f(-10, -10, 0), Vec3f(10, -10, 0), Vec3f(-10, 10, 0)});  // wide
    test::append(g, {Vec3f(-10, -10, -10), Vec3f(10, 10, 10), Vec3f(10, 10, 10.1f)});  // long diagonal sliver
    const SceneGeometry slivers = make_diagonal_slivers(1000, 6);
    for (const SceneGeometry* scene : std::initializer_list<const SceneGeometry*>{&g, &slivers}) {
        const std::vector<GridRef> triangle_refs = gridbvh::make_triangle_refs(scene->triangles);
        Box3f box;
        for (const GridRef& r : triangle_refs) box.extend(r.bounds());
        const GridFrame frame(box);
        for (float budget : {0.0f, 0.05f, 0.3f, 2.0f}) {
            SCOPED_TRACE("budget " + std::to_string(budget));
            const std::vector<GridRef> refs =
                gridbvh::split_into_partial_triangles(scene->triangles, triangle_refs, frame, budget);
            const size_t n = scene->triangles.size();
            EXPECT_LE(refs.size(), size_t(std::floor(double(budget) * double(n))) + n);
            // The budget is used: by the few huge triangles of the first scene,
            // and (shares rounded down, formula of §4.4) by the equally long
            // slivers once it reaches a split per sliver.
            if (scene == &g ? budget >= 0.05f : budget >= 2.0f) EXPECT_GT(refs.size(), n + n / 50);
            if (budget == 0.0f) EXPECT_EQ(refs.size(), n);
            std::vector<std::vector<Box3f>> parts(n);
            for (const GridRef& r : refs) {
                ASSERT_LT(r.prim, n);
                const Triangle& tri = scene->triangles[r.prim];
                EXPECT_FALSE(r.bounds().is_empty());
                EXPECT_TRUE(tri.bounds().contains(r.bounds()));
                // Tight: clipping the triangle to the part box gives (nearly) the part box back.
                const Box3f again = gridbvh::clip_triangle_to_box(tri, r.bounds());
                const float tol = 1e-4f * length(box.extent());
                EXPECT_TRUE(r.bounds().contains(again));
                for (int a = 0; a < 3; ++a) {
                    EXPECT_LE(again.lo[a] - r.lo[a], tol);
                    EXPECT_LE(r.hi[a] - again.hi[a], tol);
                }
                parts[r.prim].push_back(r.bounds());
            }
            // Every triangle has a part, and points of a triangle lie in some part.
            std::mt19937 rng(2);
            std::uniform_real_distribution<float> unit(0.0f, 1.0f);
            for (size_t t = 0; t < n; ++t) {
                ASSERT_FALSE(parts[t].empty()) << "triangle " << t << " lost";
                if (parts[t].size() == 1) continue;
                const Triangle& tri = scene->triangles[t];
                for (int s = 0; s < 20; ++s) {
                    float b1 = unit(rng), b2 = unit(rng);
                    if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
                    const Vec3f p = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
                    EXPECT_TRUE(std::any_of(parts[t].begin(), parts[t].end(),
                                            [&](const Box3f& b) { return b.contains(Box3f{p, p}); }));
                }
            }
            if (scene == &g && budget == 2.0f) {
                // The wide triangle is cut along both axes (pass 2): some part is
                // much narrower than the triangle in x and in y.
                const auto& wide = parts[n - 2];
                EXPECT_GT(wide.size(), 100u);
                EXPECT_TRUE(std::any_of(wide.begin(), wide.end(),
                                        [](const Box3f& b) { return b.extent().x < 2.0f && b.extent().y < 2.0f; }));
            }
        }
    }
}

// ------------------------------------------------------- structural invariants

TEST(GridBvh, InvariantsHoldForScenesLeafSizesAndThreads) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (int threads : {1, 2}) {
                SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " threads " +
                             std::to_string(threads));
                const BuildOptions options{.builder = Builder::GridBvh, .threads = threads, .max_leaf_size = leaf_size};
                check_bvh(build_bvh(scene.geometry.triangles, options), scene.geometry.triangles, leaf_size);
            }
        }
    }
}

TEST(GridBvhSplit, InvariantsHoldForScenesLeafSizesAndBudgets) {
    for (const NamedScene& scene : test_scenes()) {
        for (int leaf_size : {1, 4, 16}) {
            for (float budget : {0.3f, 2.0f}) {
                SCOPED_TRACE(scene.name + " leaf " + std::to_string(leaf_size) + " budget " + std::to_string(budget));
                const Bvh bvh = build_grid_bvh(scene.geometry.triangles, BvhBuildConfig{.max_leaf_size = leaf_size},
                                               GridBvhOptions{.split_budget = budget}, true);
                check_bvh(bvh, scene.geometry.triangles, leaf_size, Refs::Partial);
                EXPECT_LE(bvh.prim_indices.size(),
                          size_t(std::floor(double(budget) * double(scene.geometry.size()))) + scene.geometry.size());
            }
        }
    }
}

TEST(GridBvh, EmptyAndSingleTriangle) {
    for (bool split : {false, true}) {
        const Bvh empty = build_grid_bvh({}, BvhBuildConfig{}, GridBvhOptions{}, split);
        EXPECT_TRUE(empty.nodes.empty());
        EXPECT_TRUE(empty.prim_indices.empty());
        const Triangle tri{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)};
        const Bvh one = build_grid_bvh(std::span<const Triangle>(&tri, 1), BvhBuildConfig{}, GridBvhOptions{}, split);
        ASSERT_EQ(one.nodes.size(), 1u);
        EXPECT_EQ(one.nodes[0].count, 1u);
        EXPECT_TRUE(same_box(one.nodes[0].bounds, tri.bounds()));
    }
}

TEST(GridBvh, DepthStaysWithinLimitOnPathologicalInput) {
    const SceneGeometry row = make_geometric_row(900);
    const SceneGeometry same = make_identical(10000);
    for (bool split : {false, true}) {
        for (int leaf_size : {1, 4}) {
            SCOPED_TRACE(std::string(split ? "split" : "plain") + " leaf " + std::to_string(leaf_size));
            const BvhBuildConfig config{.max_leaf_size = leaf_size};
            check_bvh(build_grid_bvh(row.triangles, config, GridBvhOptions{}, split), row.triangles, leaf_size,
                      refs_of(split));
            const TreeShape shape = check_bvh(build_grid_bvh(same.triangles, config, GridBvhOptions{}, split),
                                              same.triangles, leaf_size, refs_of(split));
            EXPECT_LE(shape.max_depth, kBvhMaxDepth);
        }
    }
}

TEST(GridBvh, SameTreeForEveryThreadCount) {
    SceneGeometry soup = test::make_triangle_soup(60000, 5, {Vec3f(-100.0f), Vec3f(100.0f)}, 1.0f);
    const SceneGeometry slivers = make_diagonal_slivers(3000, 9);
    for (const Triangle& t : slivers.triangles) test::append(soup, {t.v0 * 10.0f, t.v1 * 10.0f, t.v2 * 10.0f});
    for (bool split : {false, true}) {
        SCOPED_TRACE(split ? "split" : "plain");
        const Builder builder = split ? Builder::GridBvhSplit : Builder::GridBvh;
        const Bvh one = build_bvh(soup.triangles, BuildOptions{.builder = builder, .threads = 1});
        const Bvh two = build_bvh(soup.triangles, BuildOptions{.builder = builder, .threads = 2});
        const Bvh all = build_bvh(soup.triangles, BuildOptions{.builder = builder, .threads = 0});
        EXPECT_TRUE(identical(one, two));
        EXPECT_TRUE(identical(one, all));
        check_bvh(one, soup.triangles, 4, refs_of(split));
    }
}

TEST(GridBvh, SameTreeForEveryThreadCountWithCrowdedCells) {
    // Most triangles in a few Grid0 cells: large leaves finished in parallel.
    SceneGeometry g = test::make_triangle_soup(20000, 15, {Vec3f(0.0f), Vec3f(0.05f)}, 0.01f);
    test::append(g, {Vec3f(-100.0f), Vec3f(-100.0f, -99.0f, -100.0f), Vec3f(-100.0f, -100.0f, -99.0f)});
    test::append(g, {Vec3f(100.0f), Vec3f(100.0f, 99.0f, 100.0f), Vec3f(100.0f, 100.0f, 99.0f)});
    for (const Triangle& t : make_identical(6000).triangles) test::append(g, t);
    for (bool split : {false, true}) {
        SCOPED_TRACE(split ? "split" : "plain");
        GridBvhStages stages;
        const Bvh one = parallel::with_threads(
            1, [&] { return build_grid_bvh(g.triangles, BvhBuildConfig{}, GridBvhOptions{}, split, &stages); });
        const Builder builder = split ? Builder::GridBvhSplit : Builder::GridBvh;
        const Bvh two = build_bvh(g.triangles, BuildOptions{.builder = builder, .threads = 2});
        EXPECT_GT(stages.large_leaves, 0u);
        EXPECT_TRUE(identical(one, two));
        check_bvh(one, g.triangles, 4, refs_of(split));
    }
}

TEST(GridBvh, MemoryBudgetFailureThrowsError) {
    const SceneGeometry soup = test::make_triangle_soup(5000, 16, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    const size_t previous = set_memory_budget(1 << 20);  // TopGrid0 alone needs 8 MB
    EXPECT_THROW((void)build_grid_bvh(soup.triangles, BvhBuildConfig{}, GridBvhOptions{}, false), Error);
    EXPECT_THROW((void)build_grid_bvh(soup.triangles, BvhBuildConfig{}, GridBvhOptions{}, true), Error);
    set_memory_budget(previous);
    EXPECT_NO_THROW((void)build_grid_bvh(soup.triangles, BvhBuildConfig{}, GridBvhOptions{}, true));
}

TEST(GridBvh, StagesAreReported) {
    const SceneGeometry g = make_diagonal_slivers(2000, 12);
    GridBvhStages stages;
    const Bvh bvh = build_grid_bvh(g.triangles, BvhBuildConfig{}, GridBvhOptions{.split_budget = 2.0f}, true, &stages);
    EXPECT_EQ(stages.triangles, g.size());
    EXPECT_GT(stages.references, g.size());
    EXPECT_GT(stages.occupied_top_cells, 0u);
    EXPECT_GT(stages.grid_bytes, 0u);
    EXPECT_GT(stages.hierarchy_leaves, 0u);
    EXPECT_GE(stages.total_ms, stages.hierarchy_ms);
    EXPECT_GE(stages.total_ms, 0.0);
    EXPECT_FALSE(bvh.nodes.empty());
}

// ------------------------------------------------------------------ quality

TEST(GridBvhSplit, PartialTrianglesLowerSahOnLongThinTriangles) {
    // Long thin diagonal triangles among small ones: the default budget goes
    // to the long ones.
    SceneGeometry mixed = test::make_triangle_soup(4000, 14, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.2f);
    for (const Triangle& t : make_diagonal_slivers(300, 13).triangles) test::append(mixed, t);
    const double mixed_plain = build_grid_bvh(mixed.triangles, BvhBuildConfig{}, GridBvhOptions{}, false).sah_cost();
    const double mixed_split = build_grid_bvh(mixed.triangles, BvhBuildConfig{}, GridBvhOptions{}, true).sah_cost();
    EXPECT_LT(mixed_split, 0.9 * mixed_plain);
    // Only long thin triangles: a larger budget is needed (a few halved
    // triangles among many long ones do not lower the SAH, with any builder).
    const SceneGeometry slivers = make_diagonal_slivers(4000, 13);
    const double plain = build_grid_bvh(slivers.triangles, BvhBuildConfig{}, GridBvhOptions{}, false).sah_cost();
    const double split =
        build_grid_bvh(slivers.triangles, BvhBuildConfig{}, GridBvhOptions{.split_budget = 2.0f}, true).sah_cost();
    EXPECT_LT(split, 0.8 * plain);
    // The grid's approximate SAH stays near the binned builder's quality.
    const double binned = build_binned_sah(slivers.triangles, BvhBuildConfig{}, BinnedSahOptions{}).sah_cost();
    EXPECT_LT(plain, 1.25 * binned);
    std::printf("SAH mixed: gridbvh %.1f split %.1f; slivers: binned %.1f gridbvh %.1f split(2.0) %.1f\n", mixed_plain,
                mixed_split, binned, plain, split);
}

// ------------------------------------------------------ traversal vs brute force

using test::make_rays;

void compare_with_brute_force(const SceneGeometry& g, const BuildOptions& options, size_t ray_count, uint32_t seed) {
    const auto accel = build_accel(g, options);
    const BruteForceAccel brute(g);
    size_t hits = 0;
    for (const Ray& ray : make_rays(g, ray_count, seed)) {
        const Hit expected = brute.intersect(ray);
        const Hit got = accel->intersect(ray);
        ASSERT_EQ(got.found(), expected.found());
        if (expected.found()) {
            if (got.prim != expected.prim) {
                EXPECT_NEAR(got.t, expected.t, 1e-5f * std::fabs(expected.t));
            } else {
                EXPECT_EQ(got.t, expected.t);
            }
            EXPECT_GE(got.t, ray.tmin);
            EXPECT_LE(got.t, ray.tmax);
        }
        EXPECT_EQ(accel->occluded(ray), expected.found());
        hits += expected.found();
    }
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
}

TEST(GridBvh, TraversalMatchesBruteForce) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    const SceneGeometry nasty = test::make_nasty_geometry(4);
    const SceneGeometry far = test::make_triangle_soup(2000, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    const SceneGeometry huge = test::make_triangle_soup(2000, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    const SceneGeometry slivers = make_diagonal_slivers(2000, 24);
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    for (Builder builder : {Builder::GridBvh, Builder::GridBvhSplit}) {
        for (int leaf : {1, 4}) {
            SCOPED_TRACE(to_string(builder) + " leaf " + std::to_string(leaf));
            const BuildOptions options{.builder = builder, .max_leaf_size = leaf, .grid_bvh = {.split_budget = 1.0f}};
            compare_with_brute_force(soup, options, 1000, 1);
            compare_with_brute_force(sphere, options, 1000, 2);
            compare_with_brute_force(nasty, options, 1500, 3);
            compare_with_brute_force(far, options, 1000, 4);
            compare_with_brute_force(huge, options, 1000, 5);
            compare_with_brute_force(slivers, options, 1000, 6);
            compare_with_brute_force(cube, options, 1000, 7);
        }
    }
}

}  // namespace
}  // namespace rf
