// Uniform grids and proximity clouds (seeds 001, 002): the SAT overlap test,
// the Chebyshev distance transform, the build invariants and the 3D-DDA
// traversal (plain and with proximity jumps) against the brute-force reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/accel_factories.h"
#include "accel/grid/grid_accel.h"
#include "accel/grid/proximity_clouds.h"
#include "accel/grid/uniform_grid.h"
#include "accel/grid/uniform_grid_steps.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "trace/grid_traversal.h"

namespace rf {
namespace {

using uniform_grid_steps::to_vec3d;
using uniform_grid_steps::triangle_overlaps_cell_box;
using SatVec3 = uniform_grid_steps::Vec3d;

// ---------------------------------------------------------------- SAT test

// Reference overlap: clip the triangle against the box's six half-spaces
// (Sutherland-Hodgman); they overlap iff something is left.
bool clip_overlap(SatVec3 lo, SatVec3 hi, const std::vector<SatVec3>& triangle) {
    std::vector<SatVec3> poly = triangle;
    for (int axis = 0; axis < 3; ++axis) {
        for (int side = 0; side < 2; ++side) {
            auto coord = [&](const SatVec3& p) { return axis == 0 ? p.x : (axis == 1 ? p.y : p.z); };
            const double bound = axis == 0 ? (side ? hi.x : lo.x) : axis == 1 ? (side ? hi.y : lo.y) : (side ? hi.z : lo.z);
            auto inside = [&](const SatVec3& p) { return side ? coord(p) <= bound : coord(p) >= bound; };
            std::vector<SatVec3> out;
            for (size_t i = 0; i < poly.size(); ++i) {
                const SatVec3 a = poly[i], b = poly[(i + 1) % poly.size()];
                if (inside(a)) out.push_back(a);
                if (inside(a) != inside(b)) {
                    const double t = (bound - coord(a)) / (coord(b) - coord(a));
                    out.push_back({a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t});
                }
            }
            poly = std::move(out);
            if (poly.empty()) return false;
        }
    }
    return true;
}

TEST(UniformGrid, SatOverlapHandPickedCases) {
    const SatVec3 c(0, 0, 0), h(1, 1, 1);
    // Inside, enclosing, far away.
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {-0.5, 0, 0}, {0.5, 0, 0}, {0, 0.5, 0}));
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {-10, -10, 0}, {10, -10, 0}, {0, 10, 0}));
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {5, 5, 5}, {6, 5, 5}, {5, 6, 5}));
    // Touching a face counts as overlap; just beyond it does not.
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {1, -3, -3}, {1, 3, -3}, {1, 0, 3}));
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {1.001, -3, -3}, {1.001, 3, -3}, {1.001, 0, 3}));
    // AABBs overlap but the plane x + y + z = 3.5 passes beyond the corner (1, 1, 1).
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {3.5, 0, 0}, {0, 3.5, 0}, {0, 0, 3.5}));
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {2.9, 0, 0}, {0, 2.9, 0}, {0, 0, 2.9}));
    // AABBs and plane overlap, but an edge axis separates: a thin triangle in
    // the plane z = 0 running diagonally past the corner (1, 1).
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {2.2, 0, 0}, {0, 2.2, 0}, {2.3, 0.1, 0}));
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {1.9, 0, 0}, {0, 1.9, 0}, {2.3, 0.1, 0}));
    // Degenerate triangles: a point, a segment (crossing / missing the box).
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}, {0.5, 0.5, 0.5}));
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {1.5, 0.5, 0.5}, {1.5, 0.5, 0.5}, {1.5, 0.5, 0.5}));
    EXPECT_TRUE(triangle_overlaps_cell_box(c, h, {-3, -3, 0}, {3, 3, 0}, {0, 0, 0}));
    EXPECT_FALSE(triangle_overlaps_cell_box(c, h, {-1, 3.5, 0}, {3.5, -1, 0}, {1.25, 1.25, 0}));
    // A non-cubic, off-centre box.
    EXPECT_TRUE(triangle_overlaps_cell_box({10, 0, 0}, {0.1, 5, 5}, {9.95, -100, -100}, {9.95, 100, -100}, {9.95, 0, 100}));
    EXPECT_FALSE(triangle_overlaps_cell_box({10, 0, 0}, {0.1, 5, 5}, {10.2, -100, -100}, {10.2, 100, -100}, {10.2, 0, 100}));
}

TEST(UniformGrid, SatOverlapMatchesPolygonClipping) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-2.5, 2.5), size(0.05, 3.0);
    const SatVec3 lo(-1, -1, -1), hi(1, 1, 1);
    int overlaps = 0, disjoint = 0;
    for (int i = 0; i < 20000; ++i) {
        const SatVec3 centre(u(rng), u(rng), u(rng));
        const double s = size(rng);
        std::vector<SatVec3> tri;
        for (int k = 0; k < 3; ++k) tri.push_back({centre.x + s * u(rng), centre.y + s * u(rng), centre.z + s * u(rng)});
        const bool sat = triangle_overlaps_cell_box({0, 0, 0}, {1, 1, 1}, tri[0], tri[1], tri[2]);
        ASSERT_EQ(sat, clip_overlap(lo, hi, tri)) << "case " << i;
        (sat ? overlaps : disjoint) += 1;
    }
    EXPECT_GT(overlaps, 2000);
    EXPECT_GT(disjoint, 2000);
}

// ---------------------------------------------------------- distance maps

std::vector<uint32_t> brute_chebyshev(const std::vector<uint8_t>& occupied, std::array<int, 3> d) {
    std::vector<uint32_t> out(occupied.size(), kNoOccupiedCell);
    for (int z = 0; z < d[2]; ++z)
        for (int y = 0; y < d[1]; ++y)
            for (int x = 0; x < d[0]; ++x) {
                uint32_t best = kNoOccupiedCell;
                for (int z2 = 0; z2 < d[2]; ++z2)
                    for (int y2 = 0; y2 < d[1]; ++y2)
                        for (int x2 = 0; x2 < d[0]; ++x2) {
                            if (!occupied[x2 + d[0] * (y2 + d[1] * z2)]) continue;
                            const int dist = std::max({std::abs(x - x2), std::abs(y - y2), std::abs(z - z2)});
                            best = std::min(best, static_cast<uint32_t>(dist));
                        }
                out[x + d[0] * (y + d[1] * z)] = best;
            }
    return out;
}

TEST(ProximityGrid, DistanceTransformMatchesBruteForce) {
    std::mt19937 rng(5);
    std::uniform_int_distribution<int> dim(1, 11);
    for (int trial = 0; trial < 120; ++trial) {
        const std::array<int, 3> d{dim(rng), dim(rng), dim(rng)};
        const size_t cells = size_t(d[0]) * d[1] * d[2];
        const double density = trial % 4 == 0 ? 0.0 : std::pow(0.5, trial % 7);
        std::bernoulli_distribution occupied_cell(density);
        std::vector<uint8_t> occupied(cells);
        for (auto& o : occupied) o = occupied_cell(rng) ? 1 : 0;
        if (trial % 4 == 1) {  // a single occupied cell
            std::fill(occupied.begin(), occupied.end(), 0);
            occupied[rng() % cells] = 1;
        }
        ASSERT_EQ(chebyshev_distance_transform(occupied, d), brute_chebyshev(occupied, d))
            << "dims " << d[0] << "x" << d[1] << "x" << d[2] << " density " << density;
    }
    // Long lines (one axis much longer than the others).
    std::vector<uint8_t> line(300, 0);
    line[17] = line[250] = 1;
    EXPECT_EQ(chebyshev_distance_transform(line, {1, 300, 1}), brute_chebyshev(line, {1, 300, 1}));
    EXPECT_THROW(chebyshev_distance_transform(line, {2, 300, 1}), Error);
}

TEST(ProximityGrid, StoredDistancesAreChebyshevDistancesToNonEmptyCells) {
    const SceneGeometry soup = test::make_triangle_soup(60, 31, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.3f);
    const UniformGrid grid = build_uniform_grid(soup.triangles, 18, true);
    const auto d = grid.layout.dims;
    ASSERT_EQ(grid.proximity.size(), grid.cell_count());
    std::vector<uint8_t> occupied(grid.cell_count());
    for (size_t c = 0; c < occupied.size(); ++c) occupied[c] = grid.cell_start[c + 1] > grid.cell_start[c];
    const std::vector<uint32_t> expected = brute_chebyshev(occupied, d);
    size_t far_cells = 0;
    for (size_t c = 0; c < expected.size(); ++c) {
        ASSERT_EQ(grid.proximity[c], std::min<uint32_t>(expected[c], 255)) << "cell " << c;
        far_cells += expected[c] >= 3;
    }
    EXPECT_GT(far_cells, grid.cell_count() / 4);  // the scene is sparse enough to skip
}

// ------------------------------------------------------------ the build

TEST(UniformGrid, EveryCellOverlappingATriangleHoldsIt) {
    for (const SceneGeometry& g : {test::make_nasty_geometry(3),
                                   test::make_triangle_soup(400, 32, {Vec3f(-3.0f), Vec3f(3.0f)}, 1.5f),
                                   test::make_triangle_soup(200, 33, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 5.0f)}) {
        for (int resolution : {0, 1, 7, 20}) {
            const UniformGrid grid = build_uniform_grid(g.triangles, resolution, false);
            const auto d = grid.layout.dims;
            ASSERT_EQ(grid.cell_start.size(), grid.cell_count() + 1);
            EXPECT_EQ(grid.cell_start.back(), grid.cell_prims.size());
            // Lists are sorted and free of duplicates.
            for (size_t c = 0; c < grid.cell_count(); ++c) {
                for (uint32_t s = grid.cell_start[c] + 1; s < grid.cell_start[c + 1]; ++s)
                    ASSERT_LT(grid.cell_prims[s - 1], grid.cell_prims[s]);
            }
            for (uint32_t t = 0; t < g.triangles.size(); ++t) {
                const Triangle& tri = g.triangles[t];
                // Cells beyond the triangle's bounds (plus slack) cannot overlap it.
                const Box3f bb = tri.bounds();
                int lo[3], hi[3];
                for (int a = 0; a < 3; ++a) {
                    const float inv = 1.0f / grid.layout.cell_size;
                    lo[a] = std::clamp(int(std::floor((bb.lo[a] - grid.layout.origin[a]) * inv)) - 2, 0, d[a] - 1);
                    hi[a] = std::clamp(int(std::floor((bb.hi[a] - grid.layout.origin[a]) * inv)) + 2, 0, d[a] - 1);
                }
                size_t overlapped = 0;
                for (int z = lo[2]; z <= hi[2]; ++z)
                    for (int y = lo[1]; y <= hi[1]; ++y)
                        for (int x = lo[0]; x <= hi[0]; ++x) {
                            const Box3f box = grid.cell_box(x, y, z);
                            const SatVec3 centre = to_vec3d(box.center()), half = to_vec3d(box.extent() * 0.5f);
                            if (!triangle_overlaps_cell_box(centre, half, to_vec3d(tri.v0), to_vec3d(tri.v1),
                                                            to_vec3d(tri.v2)))
                                continue;
                            ++overlapped;
                            const size_t c = size_t(x) + size_t(d[0]) * (size_t(y) + size_t(d[1]) * size_t(z));
                            const auto begin = grid.cell_prims.begin() + grid.cell_start[c];
                            const auto end = grid.cell_prims.begin() + grid.cell_start[c + 1];
                            ASSERT_TRUE(std::binary_search(begin, end, t))
                                << "triangle " << t << " missing from cell " << x << "," << y << "," << z
                                << " (resolution " << resolution << ")";
                        }
                ASSERT_GE(overlapped, 1u) << "triangle " << t << " overlaps no cell";
            }
        }
    }
}

TEST(UniformGrid, ResolutionRules) {
    const Box3f cube{Vec3f(-1.0f), Vec3f(1.0f)};
    // Zlatuška 2009: floor(4 * n^(1/4)) cells on the shortest axis, cubic cells.
    GridLayout layout = choose_grid_layout(cube, 4000, 0);
    EXPECT_EQ(layout.dims, (std::array<int, 3>{31, 31, 31}));
    const Box3f slab{Vec3f(0.0f, 0.0f, 0.0f), Vec3f(4.0f, 2.0f, 1.0f)};
    layout = choose_grid_layout(slab, 10001, 0);  // floor(4 * 10001^(1/4)) = 40 on z
    EXPECT_EQ(layout.dims[2], 40);
    EXPECT_NEAR(layout.dims[0], 160, 1);
    EXPECT_NEAR(layout.dims[1], 80, 1);
    // Explicit: cells on the longest axis.
    layout = choose_grid_layout(slab, 10, 64);
    EXPECT_EQ(layout.dims[0], 64);
    EXPECT_NEAR(layout.dims[1], 32, 1);
    EXPECT_NEAR(layout.dims[2], 16, 1);
    // A flat scene gets one cell across its flat axis; a thin one is capped.
    layout = choose_grid_layout({Vec3f(0.0f), Vec3f(2.0f, 2.0f, 0.0f)}, 300, 0);
    EXPECT_EQ(layout.dims[2], 1);
    EXPECT_EQ(layout.dims[0], 16);  // 4 * 300^(1/4) = 16.6 on the shortest non-flat axis
    layout = choose_grid_layout({Vec3f(0.0f), Vec3f(1000.0f, 1.0f, 1e-3f)}, 300, 0);
    EXPECT_LE(layout.cell_count(), size_t(8 * 16 * 16 * 16));
    // The grid box contains the bounds.
    for (const Box3f& b : {cube, slab, Box3f{Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, Box3f{Vec3f(3.0f), Vec3f(3.0f)}}) {
        for (int res : {0, 1, 13}) {
            layout = choose_grid_layout(b, 100, res);
            for (int a = 0; a < 3; ++a) {
                EXPECT_LE(layout.origin[a], b.lo[a]);
                EXPECT_GE(layout.origin[a] + static_cast<float>(layout.dims[a]) * layout.cell_size, b.hi[a]);
                EXPECT_GE(layout.dims[a], 1);
            }
        }
    }
}

TEST(UniformGrid, InvalidOptionsAndAbsurdSizesThrow) {
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(4));
    EXPECT_THROW(build_accel(cube, BuildOptions{.structure = Structure::Grid, .grid = {.resolution = -1}}), Error);
    EXPECT_THROW(build_accel(cube, BuildOptions{.structure = Structure::Grid, .grid = {.resolution = 4096}}), Error);
    EXPECT_THROW(make_grid_accel(cube, BuildOptions{.structure = Structure::Bvh}), Error);
    EXPECT_THROW(
        make_grid_accel(cube, BuildOptions{.structure = Structure::ProximityGrid, .grid = {.resolution = 9999}}),
        Error);
    EXPECT_THROW(make_grid_accel(cube, BuildOptions{.structure = Structure::Grid, .threads = -2}), Error);
    // 2048^3 cells do not fit 32-bit cell indices.
    EXPECT_THROW(build_accel(cube, BuildOptions{.structure = Structure::Grid, .grid = {.resolution = 2048}}), Error);
    // Over the memory budget: a one-line rf::Error, not bad_alloc.
    const size_t previous = set_memory_budget(size_t(1) << 20);
    EXPECT_THROW(build_accel(cube, BuildOptions{.structure = Structure::ProximityGrid, .grid = {.resolution = 256}}),
                 Error);
    set_memory_budget(previous);
}

TEST(UniformGrid, BuildIsDeterministicAcrossThreadCounts) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 34, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.6f);
    const auto one = make_grid_accel(soup, BuildOptions{.structure = Structure::ProximityGrid, .threads = 1});
    const auto all = make_grid_accel(soup, BuildOptions{.structure = Structure::ProximityGrid, .threads = 0});
    const UniformGrid& a = dynamic_cast<const GridAccel&>(*one).structure();
    const UniformGrid& b = dynamic_cast<const GridAccel&>(*all).structure();
    EXPECT_EQ(a.cell_start, b.cell_start);
    EXPECT_EQ(a.cell_prims, b.cell_prims);
    EXPECT_EQ(a.proximity, b.proximity);
}

// --------------------------------------------------------- traversal

// A mix of rays (as in bvh_traversal_test.cpp): random origins and directions,
// rays aimed at triangles, zero direction components, [tmin, tmax] limits.
using test::make_rays;

void expect_same_closest(const Hit& got, const Hit& brute, const Ray& ray) {
    ASSERT_EQ(got.found(), brute.found());
    if (!brute.found()) return;
    if (got.prim != brute.prim) {
        // Another triangle at (almost) the same distance: shared edges, duplicates.
        EXPECT_NEAR(got.t, brute.t, 1e-5f * std::fabs(brute.t)) << "grid prim " << got.prim << " brute prim "
                                                                 << brute.prim;
    } else {
        EXPECT_EQ(got.t, brute.t);
        EXPECT_EQ(got.u, brute.u);
        EXPECT_EQ(got.v, brute.v);
    }
    EXPECT_GE(got.t, ray.tmin);
    EXPECT_LE(got.t, ray.tmax);
}

void compare_with_brute_force(const SceneGeometry& g, std::initializer_list<int> resolutions, size_t ray_count,
                              uint32_t seed) {
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = make_rays(g, ray_count, seed);
    std::vector<Hit> expected(rays.size());
    brute.intersect(rays, expected);
    size_t hits = 0;
    for (const Hit& h : expected) hits += h.found();
    // The rays must exercise both outcomes.
    EXPECT_GT(hits, ray_count / 5);
    EXPECT_LT(hits, ray_count);
    for (int resolution : resolutions) {
      for (Structure structure : {Structure::Grid, Structure::ProximityGrid}) {
        SCOPED_TRACE(to_string(structure) + " resolution " + std::to_string(resolution));
        const auto grid = build_accel(g, BuildOptions{.structure = structure, .grid = {.resolution = resolution}});
        for (size_t i = 0; i < rays.size(); ++i) {
            SCOPED_TRACE("ray " + std::to_string(i));
            expect_same_closest(grid->intersect(rays[i]), expected[i], rays[i]);
            EXPECT_EQ(grid->occluded(rays[i]), expected[i].found());
        }
      }
    }
}

TEST(UniformGrid, MatchesBruteForceOnTriangleSoup) {
    const SceneGeometry soup = test::make_triangle_soup(3000, 21, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.7f);
    compare_with_brute_force(soup, {0, 1, 16, 70}, 1500, 1);
}

TEST(UniformGrid, MatchesBruteForceOnTessellatedSphereAndCube) {
    const SceneGeometry sphere = test::to_geometry(test::make_icosphere(4), 3.0f);
    compare_with_brute_force(sphere, {0, 5, 40}, 2000, 2);
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(8));
    compare_with_brute_force(cube, {0, 8, 16, 33}, 2000, 3);
}

TEST(UniformGrid, MatchesBruteForceOnDegenerateAndThinTriangles) {
    const SceneGeometry nasty = test::make_nasty_geometry(4);
    compare_with_brute_force(nasty, {0, 1, 24, 64}, 3000, 4);
}

TEST(UniformGrid, MatchesBruteForceFarFromTheOrigin) {
    const SceneGeometry far = test::make_triangle_soup(1500, 22, {Vec3f(1e6f), Vec3f(1e6f + 50.0f)}, 2.0f);
    compare_with_brute_force(far, {0, 64}, 2000, 5);
    const SceneGeometry huge = test::make_triangle_soup(1500, 23, {Vec3f(-1e6f), Vec3f(1e6f)}, 3e4f);
    compare_with_brute_force(huge, {0, 100}, 2000, 6);
}

TEST(UniformGrid, MatchesBruteForceOnAFlatScene) {
    // Every triangle in the plane z = 0.5: a flat axis (one cell across it).
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(-5.0f, 5.0f);
    SceneGeometry flat;
    for (int i = 0; i < 800; ++i) {
        const Vec3f c(u(rng), u(rng), 0.5f);
        test::append(flat, {c, c + Vec3f(u(rng) * 0.1f, u(rng) * 0.1f, 0.0f), c + Vec3f(u(rng) * 0.1f, u(rng) * 0.1f, 0.0f)});
    }
    flat.normal_matrices.push_back(Affine3f::identity());
    compare_with_brute_force(flat, {0, 1, 32}, 2000, 8);
    const UniformGrid grid = build_uniform_grid(flat.triangles, 32, false);
    EXPECT_EQ(grid.layout.dims[2], 1);
}

TEST(UniformGrid, RaysFromFarAwayAimedAtTheSurface) {
    // Origins 30 scene sizes away: the walk must start from an accurate entry
    // point, not from crossing distances rounded at the origin's distance.
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(20));
    const BruteForceAccel brute(cube);
    std::mt19937 rng(12);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays;
    for (int i = 0; i < 2000; ++i) {
        const Triangle& tri = cube.triangles[rng() % cube.size()];
        float b1 = unit(rng), b2 = unit(rng);
        if (b1 + b2 > 1.0f) { b1 = 1.0f - b1; b2 = 1.0f - b2; }
        const Vec3f target = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2;
        const Vec3f dir = test::random_direction(rng);
        rays.push_back(Ray{target - dir * 100.0f, 0.0f, dir});
    }
    std::vector<Hit> expected(rays.size());
    brute.intersect(rays, expected);
    for (Structure structure : {Structure::Grid, Structure::ProximityGrid}) {
        for (int resolution : {0, 120}) {
            const auto grid =
                build_accel(cube, BuildOptions{.structure = structure, .grid = {.resolution = resolution}});
            for (size_t i = 0; i < rays.size(); ++i) {
                expect_same_closest(grid->intersect(rays[i]), expected[i], rays[i]);
                EXPECT_EQ(grid->occluded(rays[i]), expected[i].found());
            }
        }
    }
}

TEST(UniformGrid, AxisAlignedRaysAlongCellBoundaries) {
    // The tessellated cube's vertices lie on cell boundaries at resolution 6
    // (cells of 1/3): zero direction components with origins on boundary planes.
    const SceneGeometry cube = test::to_geometry(test::make_tessellated_cube(6));
    const BruteForceAccel brute(cube);
    for (Structure structure : {Structure::Grid, Structure::ProximityGrid}) {
        for (int resolution : {6, 12, 0}) {
            const auto grid =
                build_accel(cube, BuildOptions{.structure = structure, .grid = {.resolution = resolution}});
            int hits = 0;
            for (int i = -6; i <= 6; ++i) {
                for (int j = -6; j <= 6; ++j) {
                    const float a = static_cast<float>(i) / 3.0f, b = static_cast<float>(j) / 3.0f;
                    for (const Ray& ray : {Ray{Vec3f(a, b, -5.0f), 0.0f, Vec3f(0, 0, 1)},
                                           Ray{Vec3f(5.0f, a, b), 0.0f, Vec3f(-1, 0, 0)},
                                           Ray{Vec3f(a, -5.0f, b), 0.0f, Vec3f(0, 2, 0)},
                                           Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(0, 0, -1)},
                                           Ray{Vec3f(a, b, 0.0f), 0.0f, Vec3f(1, 1, 0)}}) {
                        const Hit expected = brute.intersect(ray);
                        expect_same_closest(grid->intersect(ray), expected, ray);
                        EXPECT_EQ(grid->occluded(ray), expected.found());
                        hits += expected.found();
                    }
                }
            }
            EXPECT_GT(hits, 100);
        }
    }
}

TEST(UniformGrid, EmptySceneAndDegenerateRaysMiss) {
    const SceneGeometry empty;
    for (Structure structure : {Structure::Grid, Structure::ProximityGrid}) {
        const auto grid = build_accel(empty, BuildOptions{.structure = structure});
        const Ray ray{Vec3f(0.0f), 0.0f, Vec3f(0, 0, 1)};
        EXPECT_FALSE(grid->intersect(ray).found());
        EXPECT_FALSE(grid->occluded(ray));
        EXPECT_EQ(grid->stats().node_count, 0u);
    }
    const SceneGeometry soup = test::make_triangle_soup(100, 35, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.5f);
    const auto grid = build_accel(soup, BuildOptions{.structure = Structure::ProximityGrid});
    EXPECT_FALSE(grid->intersect(Ray{Vec3f(0.0f), 0.0f, Vec3f(0.0f)}).found());           // zero direction
    EXPECT_FALSE(grid->intersect(Ray{Vec3f(0.0f), 2.0f, Vec3f(1, 0, 0), 1.0f}).found());  // tmin > tmax
    EXPECT_FALSE(grid->intersect(Ray{Vec3f(0.0f, 50.0f, 0.0f), 0.0f, Vec3f(1, 0, 0)}).found());  // parallel, outside
}

TEST(UniformGrid, BatchesStatsAndCountsAgreeWithSingleRays) {
    const SceneGeometry soup = test::make_triangle_soup(2000, 24, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    const std::vector<Ray> rays = make_rays(soup, 1500, 9);
    for (Structure structure : {Structure::Grid, Structure::ProximityGrid}) {
        const auto accel = build_accel(soup, BuildOptions{.structure = structure, .grid = {.resolution = 32}});
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

        const AccelStats stats = accel->stats();
        EXPECT_EQ(stats.name, to_string(structure) + "/32x32x32");
        EXPECT_EQ(stats.node_count, 32u * 32u * 32u);
        EXPECT_GT(stats.leaf_count, 0u);
        EXPECT_LT(stats.leaf_count, stats.node_count);
        EXPECT_GT(stats.bytes, stats.node_count * 4);
        EXPECT_TRUE(std::isnan(stats.sah_cost));
        EXPECT_TRUE(std::isnan(stats.quality_cost));

        TraversalTotals closest, any;
        ASSERT_TRUE(accel->count_traversal(rays, false, closest));
        ASSERT_TRUE(accel->count_traversal(rays, true, any));
        EXPECT_EQ(closest.rays, rays.size());
        EXPECT_GT(closest.steps, 0u);
        EXPECT_GT(closest.prim_tests, 0u);
        EXPECT_LE(any.prim_tests, closest.prim_tests);
        EXPECT_LT(closest.prim_tests, uint64_t(rays.size()) * soup.size() / 20);  // far fewer than brute force
    }
}

TEST(ProximityGrid, JumpsVisitFewerCellsWithTheSameHits) {
    // A sparse scene at a high resolution: most cells are far from geometry.
    const SceneGeometry sparse = test::make_triangle_soup(40, 36, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.8f);
    const auto plain = make_grid_accel(sparse, BuildOptions{.structure = Structure::Grid, .grid = {.resolution = 96}});
    const auto cloud =
        make_grid_accel(sparse, BuildOptions{.structure = Structure::ProximityGrid, .grid = {.resolution = 96}});
    const std::vector<Ray> rays = make_rays(sparse, 2000, 10);
    const GridView plain_view = dynamic_cast<const GridAccel&>(*plain).tracer().grid;
    const GridView cloud_view = dynamic_cast<const GridAccel&>(*cloud).tracer().grid;
    GridTraversalCounters plain_counts, cloud_counts;
    for (const Ray& ray : rays) {
        const Hit a = grid_intersect_counted(plain_view, ray, plain_counts);
        const Hit b = grid_intersect_counted(cloud_view, ray, cloud_counts);
        ASSERT_EQ(a.prim, b.prim);
        ASSERT_EQ(a.t, b.t);
    }
    EXPECT_EQ(plain_counts.prims_tested, cloud_counts.prims_tested);  // same non-empty cells visited
    EXPECT_LT(cloud_counts.cells_visited * 3, plain_counts.cells_visited);
}

}  // namespace
}  // namespace rf
