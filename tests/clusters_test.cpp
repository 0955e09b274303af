// Cluster-based BVH builds (Garanzha 2014 ch. 3): cluster generation
// (coverage, dual-graph connectivity, Acc > 0, determinism, the Naive
// baseline, the merge queue's order, degenerate input) and the BVH over
// cluster boxes (invariants, leaf sizes, hits equal brute force on a
// deforming mesh over several frames). DISABLED_ClustersBench measures the
// 800K-triangle case.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <random>
#include <vector>

#include "accel/accel_factories.h"
#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/cluster_generation.h"
#include "accel/bvh/builders/clusters.h"
#include "accel/bvh/bvh_accel.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel/update/bvh_updater.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "bvh_invariants.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf {
namespace {

using test::IndexedMesh;

// An n x n grid of quads over [0, n]^2 with a wavy height, deformed by `t`.
IndexedMesh make_terrain(int n, float t = 0.0f) {
    IndexedMesh m;
    m.positions.reserve(size_t(n + 1) * (n + 1));
    for (int j = 0; j <= n; ++j) {
        for (int i = 0; i <= n; ++i) {
            const float x = float(i), y = float(j);
            const float h = 2.0f * std::sin(0.11f * x + t) * std::cos(0.07f * y - 0.5f * t) + 0.3f * std::sin(0.9f * x * t);
            m.positions.emplace_back(x, y, h);
        }
    }
    m.indices.reserve(size_t(n) * n * 6);
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const uint32_t a = uint32_t(j * (n + 1) + i), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
            m.indices.insert(m.indices.end(), {a, b, d, a, d, c});
        }
    }
    return m;
}

Scene scene_of(const IndexedMesh& im, std::vector<Affine3f> transforms = {Affine3f::identity()}) {
    Scene scene;
    Mesh mesh;
    mesh.positions = im.positions;
    mesh.indices = im.indices;
    scene.meshes.push_back(std::move(mesh));
    for (const Affine3f& t : transforms) scene.instances.push_back(Instance{0, t, true});
    scene.finalize();
    return scene;
}

ClusterOptions options(ClusterHeuristic h, ClusterGeneration g) {
    ClusterOptions o;
    o.heuristic = h;
    o.generation = g;
    return o;
}

const ClusterOptions kAllOptions[] = {
    options(ClusterHeuristic::Acc, ClusterGeneration::Merge),
    options(ClusterHeuristic::Acc, ClusterGeneration::Grow),
    options(ClusterHeuristic::Naive, ClusterGeneration::Merge),
    options(ClusterHeuristic::Naive, ClusterGeneration::Grow),
};

std::string name_of(const ClusterOptions& o) {
    return std::string(o.heuristic == ClusterHeuristic::Acc ? "acc" : "naive") + "/" +
           (o.generation == ClusterGeneration::Merge ? "merge" : "grow");
}

bool same_partition(const ClusterPartition& a, const ClusterPartition& b) {
    return a.first == b.first && a.triangles == b.triangles && a.vertex_first == b.vertex_first &&
           a.vertex_refs == b.vertex_refs;
}

// Every triangle in exactly one cluster, clusters sorted and within the size
// cap, vertex references naming each distinct vertex of the cluster once.
void check_partition(const ClusterPartition& p, const IndexedMesh& m) {
    const size_t n = m.indices.size() / 3;
    ASSERT_EQ(p.triangles.size(), n);
    std::vector<int> seen(n, 0);
    for (size_t c = 0; c < p.size(); ++c) {
        const auto tris = p.cluster(c);
        ASSERT_FALSE(tris.empty());
        EXPECT_LE(tris.size(), kMaxClusterTriangles);
        EXPECT_TRUE(std::is_sorted(tris.begin(), tris.end()));
        std::vector<uint32_t> verts, refs;
        for (uint32_t t : tris) {
            ASSERT_LT(t, n);
            ++seen[t];
            for (int k = 0; k < 3; ++k) verts.push_back(m.indices[3 * t + k]);
        }
        std::sort(verts.begin(), verts.end());
        verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
        for (uint64_t r : p.vertices(c)) {
            ASSERT_TRUE(std::binary_search(tris.begin(), tris.end(), uint32_t(r / 3)));
            refs.push_back(m.indices[r]);
        }
        std::sort(refs.begin(), refs.end());
        EXPECT_EQ(refs, verts);
    }
    for (size_t t = 0; t < n; ++t) ASSERT_EQ(seen[t], 1) << "triangle " << t;
}

// Whether a cluster's triangles form one component of "shares a vertex index".
bool connected(std::span<const uint32_t> tris, const IndexedMesh& m) {
    std::vector<uint32_t> component(tris.size());
    std::iota(component.begin(), component.end(), 0u);
    auto find = [&](uint32_t x) {
        while (component[x] != x) x = component[x] = component[component[x]];
        return x;
    };
    for (size_t i = 0; i < tris.size(); ++i) {
        for (size_t j = i + 1; j < tris.size(); ++j) {
            bool share = false;
            for (int a = 0; a < 3; ++a) {
                for (int b = 0; b < 3; ++b) share |= m.indices[3 * tris[i] + a] == m.indices[3 * tris[j] + b];
            }
            if (share) component[find(uint32_t(i))] = find(uint32_t(j));
        }
    }
    for (size_t i = 0; i < tris.size(); ++i) {
        if (find(uint32_t(i)) != find(0)) return false;
    }
    return true;
}

TEST(ClustersTest, CoverConnectedAndAcceptable) {
    const IndexedMesh meshes[] = {make_terrain(24), test::make_icosphere(3)};
    for (const IndexedMesh& m : meshes) {
        for (const ClusterOptions& o : kAllOptions) {
            SCOPED_TRACE(name_of(o));
            const ClusterPartition p = cluster_mesh(m.positions, m.indices, o);
            check_partition(p, m);
            EXPECT_LT(p.size(), m.indices.size() / 3 / 4);  // real clustering happened
            for (size_t c = 0; c < p.size(); ++c) {
                ASSERT_TRUE(connected(p.cluster(c), m)) << "cluster " << c;
                if (o.heuristic == ClusterHeuristic::Acc && p.cluster(c).size() > 1) {
                    EXPECT_GT(cluster_acc(m.positions, m.indices, p.cluster(c), o), 0.0) << "cluster " << c;
                }
            }
        }
    }
}

TEST(ClustersTest, DeterministicAcrossRunsAndThreads) {
    const IndexedMesh m = make_terrain(20);
    for (const ClusterOptions& o : kAllOptions) {
        SCOPED_TRACE(name_of(o));
        const ClusterPartition a = parallel::with_threads(1, [&] { return cluster_mesh(m.positions, m.indices, o); });
        const ClusterPartition b = parallel::with_threads(2, [&] { return cluster_mesh(m.positions, m.indices, o); });
        EXPECT_TRUE(same_partition(a, b));
    }
    ClusterOptions other = options(ClusterHeuristic::Acc, ClusterGeneration::Grow);
    other.seed = 7;
    const ClusterPartition a = cluster_mesh(m.positions, m.indices, options(ClusterHeuristic::Acc, ClusterGeneration::Grow));
    EXPECT_FALSE(same_partition(a, cluster_mesh(m.positions, m.indices, other)));  // the seed matters
}

TEST(ClustersTest, ParametersControlClusterSize) {
    const IndexedMesh m = make_terrain(24);
    ClusterOptions small = options(ClusterHeuristic::Acc, ClusterGeneration::Merge);
    small.max_count = small.max_size = 10;
    const size_t n_small = cluster_mesh(m.positions, m.indices, small).size();
    const size_t n_default = cluster_mesh(m.positions, m.indices, ClusterOptions{}).size();
    EXPECT_GT(n_small, n_default);
    ClusterOptions none = small;
    none.max_count = 1;  // regBound >= 3 for every pair: nothing merges
    EXPECT_EQ(cluster_mesh(m.positions, m.indices, none).size(), m.indices.size() / 3);
}

TEST(ClustersTest, NaiveStopsAtAccClusterCount) {
    const IndexedMesh m = make_terrain(24);
    const size_t acc = cluster_mesh(m.positions, m.indices, ClusterOptions{}).size();
    const ClusterPartition naive =
        cluster_mesh(m.positions, m.indices, options(ClusterHeuristic::Naive, ClusterGeneration::Merge));
    EXPECT_EQ(naive.size(), acc);
    // Naive(k) of a flat-ish patch is near 1/2 (area over box area), and a cluster's is positive.
    for (size_t c = 0; c < naive.size(); ++c) {
        const double v = cluster_naive(m.positions, m.indices, naive.cluster(c));
        EXPECT_GT(v, 0.0);
        EXPECT_LE(v, 0.5 + 1e-5);
    }
}

TEST(ClustersTest, AccMatchesHandComputedValues) {
    // Two right triangles forming the unit square: box-centred sphere radius
    // sqrt(2)/2, AreaC = pi/2, AreaP = 1, 4 vertices, AvgSA from radius sqrt(2)/2.
    const std::vector<Vec3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
    const std::vector<uint32_t> idx = {0, 1, 3, 0, 3, 2};
    ClusterOptions o;
    const double pi = 3.14159265358979323846;
    const uint32_t both[] = {0, 1};
    EXPECT_NEAR(cluster_acc(p, idx, both, o), 1.0 / (pi / 2) - 4.0 / 50.0, 1e-6);
    const uint32_t one[] = {0};
    EXPECT_NEAR(cluster_acc(p, idx, one, o), 0.5 / (pi / 2) - 3.0 / 50.0, 1e-6);
    EXPECT_NEAR(cluster_naive(p, idx, both), 1.0 / 2.0, 1e-6);  // flat box: area 2 * 1
    // sizeBound: MaxSize small enough that the sphere exceeds it.
    o.max_size = 0.25f;  // SA(S) / (MaxSize * AvgSA) = 1 / 0.25 = 4
    EXPECT_NEAR(cluster_acc(p, idx, both, o), 1.0 / (pi / 2) - 4.0 * 4.0 / 50.0, 1e-5);
    // Opposite normals cancel: N_AVG falls back to the largest triangle's.
    const std::vector<uint32_t> folded = {0, 1, 3, 0, 3, 1};
    EXPECT_NEAR(cluster_acc(p, folded, both, ClusterOptions{}), 1.0 / (pi / 2) - 3.0 / 50.0, 1e-6);
}

TEST(ClustersTest, MergeQueueOrdersByKey) {
    MergeQueue q;
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> key(-3.0f, 3.0f);
    std::vector<MergeQueue::Entry> all;
    for (uint32_t i = 0; i < 2000; ++i) {
        const float k = i % 10 == 0 ? 0.5f : key(rng);  // many ties
        all.push_back({k, i % 37, 1000 + i, 0, 0});
        q.push(all.back());
    }
    q.push({std::nanf(""), 0, 1, 0, 0});  // dropped
    EXPECT_EQ(q.size(), all.size());
    std::sort(all.begin(), all.end(), [](const auto& x, const auto& y) {
        if (x.key != y.key) return x.key > y.key;
        return x.a != y.a ? x.a < y.a : x.b < y.b;
    });
    for (const auto& want : all) {
        ASSERT_FALSE(q.empty());
        const MergeQueue::Entry got = q.pop();
        ASSERT_EQ(got.key, want.key);
        ASSERT_EQ(got.a, want.a);
        ASSERT_EQ(got.b, want.b);
    }
    EXPECT_TRUE(q.empty());
    EXPECT_EQ(MergeQueue::bucket_of(-5.0f), 0);
    EXPECT_EQ(MergeQueue::bucket_of(5.0f), MergeQueue::kBuckets - 1);
    EXPECT_LT(MergeQueue::bucket_of(0.1f), MergeQueue::bucket_of(0.11f));
}

TEST(ClustersTest, DualGraphSharesVerticesAndChainsFans) {
    const IndexedMesh m = make_terrain(3);
    const DualGraph g = build_dual_graph(m.indices, m.positions.size());
    // Triangle 0 (a, b, d of the first quad) shares vertices with its quad
    // mate, the next quad's two and the quads above.
    const auto nb = g.neighbours(0);
    EXPECT_TRUE(std::is_sorted(nb.begin(), nb.end()));
    EXPECT_TRUE(std::find(nb.begin(), nb.end(), 1u) != nb.end());
    EXPECT_TRUE(std::find(nb.begin(), nb.end(), 0u) == nb.end());
    // A fan of 100 triangles around vertex 0: a chain, not 99 edges each.
    std::vector<uint32_t> fan;
    for (uint32_t i = 0; i < 100; ++i) fan.insert(fan.end(), {0, 1 + i, 2 + i});
    const DualGraph f = build_dual_graph(fan, 102);
    for (uint32_t t = 0; t < 100; ++t) EXPECT_LE(f.neighbours(t).size(), 2u);
    EXPECT_THROW(build_dual_graph(fan, 50), Error);
}

TEST(ClustersTest, DegenerateInput) {
    // A soup: no shared vertices, every cluster one triangle.
    IndexedMesh soup;
    for (uint32_t i = 0; i < 50; ++i) {
        soup.positions.insert(soup.positions.end(), {Vec3f(float(i), 0, 0), Vec3f(float(i) + 1, 0, 0), Vec3f(float(i), 1, 0)});
        soup.indices.insert(soup.indices.end(), {3 * i, 3 * i + 1, 3 * i + 2});
    }
    for (const ClusterOptions& o : kAllOptions) {
        SCOPED_TRACE(name_of(o));
        const ClusterPartition p = cluster_mesh(soup.positions, soup.indices, o);
        check_partition(p, soup);
        EXPECT_EQ(p.size(), 50u);
    }
    // Zero-area triangles (points, lines, repeated indices) among a grid, and an isolated triangle.
    IndexedMesh bad = make_terrain(6);
    const uint32_t v = uint32_t(bad.positions.size());
    bad.positions.insert(bad.positions.end(), {Vec3f(100, 0, 0), Vec3f(100, 0, 0), Vec3f(100, 0, 0), Vec3f(50, 50, 50)});
    bad.indices.insert(bad.indices.end(), {v, v + 1, v + 2, 0, 0, 1, 3, 3, 3, 0, 1, 2, v + 3, v + 3, v});
    for (const ClusterOptions& o : kAllOptions) {
        SCOPED_TRACE(name_of(o));
        const ClusterPartition p = cluster_mesh(bad.positions, bad.indices, o);
        check_partition(p, bad);
        for (size_t c = 0; c < p.size(); ++c) EXPECT_TRUE(connected(p.cluster(c), bad));
    }
    // Every triangle a point.
    const std::vector<Vec3f> points(3, Vec3f(1, 2, 3));
    const std::vector<uint32_t> idx = {0, 1, 2, 0, 1, 2, 2, 1, 0};
    EXPECT_EQ(cluster_mesh(points, idx, ClusterOptions{}).size(), 3u);
    EXPECT_EQ(cluster_mesh(points, {}, ClusterOptions{}).size(), 0u);
    // Errors.
    const std::vector<uint32_t> out_of_range = {0, 1, 5};
    EXPECT_THROW(cluster_mesh(points, out_of_range, ClusterOptions{}), Error);
    const std::vector<uint32_t> partial = {0, 1};
    EXPECT_THROW(cluster_mesh(points, partial, ClusterOptions{}), Error);
    ClusterOptions o;
    o.max_count = 0;
    EXPECT_THROW(validate_cluster_options(o), Error);
    o = ClusterOptions{};
    o.max_size = std::nanf("");
    EXPECT_THROW(validate_cluster_options(o), Error);
    o = ClusterOptions{};
    o.leaf_triangles = 65;
    EXPECT_THROW(validate_cluster_options(o), Error);
}

// Canonical-BVH invariants (bvh_invariants.h) and the L rule: leaves hold
// whole clusters, more than L triangles only as a lone cluster. With
// subtrees, leaves hold at most `leaf` triangles and may split clusters.
void check_cluster_bvh(const Bvh& bvh, std::span<const Triangle> tris, const ClusterPartition& clusters, int leaf,
                       bool subtrees = false) {
    test::check_bvh(bvh, tris, subtrees ? leaf : int(kMaxClusterTriangles));
    if (subtrees) return;
    std::vector<uint32_t> cluster_of(tris.size());
    for (size_t c = 0; c < clusters.size(); ++c) {
        for (uint32_t t : clusters.cluster(c)) cluster_of[t] = uint32_t(c);
    }
    for (const BvhNode& node : bvh.nodes) {  // all reachable, as check_bvh verified
        if (!node.is_leaf()) continue;
        std::vector<uint32_t> in_leaf;
        for (uint32_t s = node.first; s < node.first + node.count && s < bvh.prim_indices.size(); ++s) {
            if (bvh.prim_indices[s] < tris.size()) in_leaf.push_back(cluster_of[bvh.prim_indices[s]]);
        }
        std::sort(in_leaf.begin(), in_leaf.end());
        in_leaf.erase(std::unique(in_leaf.begin(), in_leaf.end()), in_leaf.end());
        size_t whole = 0;  // leaves hold whole clusters
        for (uint32_t c : in_leaf) whole += clusters.cluster(c).size();
        EXPECT_EQ(whole, node.count);
        if (node.count > uint32_t(leaf)) EXPECT_EQ(in_leaf.size(), 1u);  // only a lone cluster exceeds L
    }
}

void expect_brute_force_hits(const SceneGeometry& g, const Bvh& bvh, uint32_t seed) {
    const BvhAccel accel(g, bvh, "clusters", 0.0);
    const BruteForceAccel brute(g);
    size_t hits = 0;
    for (const Ray& ray : test::make_rays(g, 400, seed)) {
        const Hit want = brute.intersect(ray);
        const Hit got = accel.intersect(ray);
        ASSERT_EQ(got.found(), want.found());
        EXPECT_EQ(accel.occluded(ray), want.found());
        if (!want.found()) continue;
        ++hits;
        if (got.prim != want.prim) {
            EXPECT_NEAR(got.t, want.t, 1e-5f * std::fabs(want.t));
        } else {
            EXPECT_EQ(got.t, want.t);
        }
    }
    EXPECT_GT(hits, 40u);
}

TEST(ClustersTest, BvhMatchesBruteForceOnDeformingMesh) {
    const int n = 20;
    Scene scene = scene_of(make_terrain(n), {Affine3f::identity(), Affine3f::translation(Vec3f(5.0f, 3.0f, 4.0f))});
    SceneGeometry g = SceneGeometry::build(scene);
    for (const Builder builder : {Builder::BinnedSah, Builder::Ploc, Builder::Sbvh}) {
        for (const ClusterOptions& o : {kAllOptions[0], kAllOptions[1], kAllOptions[2]}) {
            SCOPED_TRACE(name_of(o));
            BuildOptions build;
            build.builder = builder;
            build.threads = 2;
            const ClusterPartition clusters = cluster_scene(scene, g, o);
            ASSERT_EQ(clusters.triangles.size(), g.size());
            auto updater = make_cluster_updater(scene, g, build, o);
            check_cluster_bvh(updater->bvh(), g.triangles, clusters, o.leaf_triangles);
            // Frames forwards and back: the frame-1 clusters stay valid.
            for (const float t : {0.7f, 2.5f, 0.7f}) {
                scene.meshes[0].positions = make_terrain(n, t).positions;
                SceneGeometry moved = SceneGeometry::build(scene);
                g.triangles = moved.triangles;
                g.bounds = moved.bounds;
                UpdateStats stats;
                EXPECT_TRUE(updater->update(g.triangles, stats));
                check_cluster_bvh(updater->bvh(), g.triangles, clusters, o.leaf_triangles);
                expect_brute_force_hits(g, updater->bvh(), uint32_t(t * 10));
            }
            scene.meshes[0].positions = make_terrain(n).positions;
            g = SceneGeometry::build(scene);
        }
    }
}

TEST(ClustersTest, SubtreesAreRefittedAndGrafted) {
    const int n = 20;
    Scene scene = scene_of(make_terrain(n));
    SceneGeometry g = SceneGeometry::build(scene);
    for (const ClusterOptions& base : {kAllOptions[0], kAllOptions[1]}) {
        ClusterOptions o = base;
        o.cluster_subtrees = true;
        BuildOptions build;
        build.max_leaf_size = 3;
        auto updater = make_cluster_updater(scene, g, build, o);
        const ClusterPartition clusters = cluster_scene(scene, g, o);
        check_cluster_bvh(updater->bvh(), g.triangles, clusters, 3, true);
        EXPECT_LT(updater->bvh().sah_cost(), 0.9 * make_cluster_updater(scene, g, build, base)->bvh().sah_cost());
        for (const float t : {1.1f, 3.0f}) {
            scene.meshes[0].positions = make_terrain(n, t).positions;
            g.triangles = SceneGeometry::build(scene).triangles;
            g.bounds = SceneGeometry::build(scene).bounds;
            UpdateStats stats;
            EXPECT_TRUE(updater->update(g.triangles, stats));
            check_cluster_bvh(updater->bvh(), g.triangles, clusters, 3, true);
            expect_brute_force_hits(g, updater->bvh(), uint32_t(t * 10));
        }
        scene.meshes[0].positions = make_terrain(n).positions;
        g = SceneGeometry::build(scene);
    }
}

TEST(ClustersTest, LeafTriangleLimitAndSoups) {
    const IndexedMesh m = test::make_icosphere(3);
    Scene scene = scene_of(m);
    const SceneGeometry g = SceneGeometry::build(scene);
    for (const int leaf : {1, 8, 32, 64}) {
        ClusterOptions o;
        o.leaf_triangles = leaf;
        auto updater = make_cluster_updater(scene, g, BuildOptions{}, o);
        check_cluster_bvh(updater->bvh(), g.triangles, cluster_scene(scene, g, o), leaf);
        expect_brute_force_hits(g, updater->bvh(), 3);
        UpdateStats stats;
        const std::vector<Triangle> fewer(g.triangles.begin(), g.triangles.end() - 1);
        EXPECT_THROW(updater->update(fewer, stats), Error);
    }
    // A soup: one-triangle clusters, leaves of up to L of them.
    const SceneGeometry soup_g = test::make_triangle_soup(500, 3, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.5f);
    Scene soup;
    Mesh mesh;
    for (const Triangle& t : soup_g.triangles) {
        const uint32_t v = uint32_t(mesh.positions.size());
        mesh.positions.insert(mesh.positions.end(), {t.v0, t.v1, t.v2});
        mesh.indices.insert(mesh.indices.end(), {v, v + 1, v + 2});
    }
    soup.meshes.push_back(std::move(mesh));
    soup.finalize();
    const SceneGeometry sg = SceneGeometry::build(soup);
    auto updater = make_cluster_updater(soup, sg, BuildOptions{}, ClusterOptions{});
    EXPECT_EQ(cluster_scene(soup, sg, ClusterOptions{}).size(), sg.size());
    check_cluster_bvh(updater->bvh(), sg.triangles, cluster_scene(soup, sg, ClusterOptions{}), 32);
    expect_brute_force_hits(sg, updater->bvh(), 4);
    // No triangles at all.
    Scene empty;
    empty.meshes.emplace_back();
    empty.finalize();
    const SceneGeometry eg = SceneGeometry::build(empty);
    EXPECT_TRUE(make_cluster_updater(empty, eg, BuildOptions{}, ClusterOptions{})->bvh().nodes.empty());
}

// ---- Measurement (run by hand: --gtest_also_run_disabled_tests --gtest_filter='*ClustersBench*').

double ms_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

template <class F>
double best_ms(int runs, F&& f) {
    double best = 1e30;
    for (int i = 0; i < runs; ++i) {
        const auto t0 = std::chrono::steady_clock::now();
        f();
        best = std::min(best, ms_since(t0));
    }
    return best;
}

TEST(ClustersBench, DISABLED_Terrain800K) {
    const int n = 633;  // 801,378 triangles
    const Scene first = scene_of(make_terrain(n));
    SceneGeometry g = SceneGeometry::build(first);
    BuildOptions build;
    build.threads = 2;
    std::printf("triangles: %zu\n", g.size());
    Scene later = scene_of(make_terrain(n, 1.3f));  // build and trace a later frame
    const std::vector<Triangle> frame = SceneGeometry::build(later).triangles;
    const auto rays = test::make_rays(g, 200000, 9);
    Bvh tbvh;
    ClusterOptions sub = kAllOptions[0];
    sub.cluster_subtrees = true;
    ClusterOptions sub_grow = kAllOptions[1];
    sub_grow.cluster_subtrees = true;
    const char* only = std::getenv("RF_CLUSTERS_BENCH");  // e.g. "acc/grow+sub": one configuration
    for (const ClusterOptions& o : {kAllOptions[0], kAllOptions[1], kAllOptions[2], sub, sub_grow}) {
        if (only && name_of(o) + (o.cluster_subtrees ? "+sub" : "") != only) continue;
        g.triangles = SceneGeometry::build(first).triangles;
        const auto t0 = std::chrono::steady_clock::now();
        auto updater = parallel::with_threads(2, [&] { return make_cluster_updater(first, g, build, o); });
        const double setup_ms = ms_since(t0);
        const size_t clusters = cluster_scene(first, g, o).size();
        g.triangles = frame;
        UpdateStats stats;
        const double cluster_build = best_ms(5, [&] { updater->update(g.triangles, stats); });
        const double tri_build = best_ms(3, [&] { tbvh = build_bvh_on_cpu(g.triangles, build); });
        auto cacc = make_wide_bvh_accel(g, updater->bvh(), build, 0.0, "bvh8");
        auto tacc = make_wide_bvh_accel(g, tbvh, build, 0.0, "bvh8");
        std::vector<Hit> hits(rays.size());
        double trace_c = 1e30, trace_t = 1e30;
        for (int r = 0; r < 5; ++r) {  // interleaved: the machine is shared
            trace_c = std::min(trace_c, parallel::with_threads(2, [&] { return best_ms(1, [&] { cacc->intersect(rays, hits); }); }));
            trace_t = std::min(trace_t, parallel::with_threads(2, [&] { return best_ms(1, [&] { tacc->intersect(rays, hits); }); }));
        }
        TraversalTotals ct, tt;
        cacc->count_traversal(rays, false, ct);
        tacc->count_traversal(rays, false, tt);
        std::printf("%-12s%s clusters %zu (%.1f tris each), setup %.0f ms | build: clusters %.1f ms, triangles %.1f ms (%.1fx) | "
                    "SAH %.2f vs %.2f | 200K rays BVH8: %.1f vs %.1f ms (%+.1f%%), steps/ray %.1f vs %.1f, tests/ray %.1f vs %.1f\n",
                    name_of(o).c_str(), o.cluster_subtrees ? "+sub" : "    ", clusters, double(g.size()) / clusters,
                    setup_ms, cluster_build, tri_build, tri_build / cluster_build, updater->bvh().sah_cost(),
                    tbvh.sah_cost(), trace_c, trace_t, 100.0 * (trace_c / trace_t - 1.0), double(ct.steps) / ct.rays,
                    double(tt.steps) / tt.rays, double(ct.prim_tests) / ct.rays, double(tt.prim_tests) / tt.rays);
    }
}

}  // namespace
}  // namespace rf

namespace rf {
namespace {

// A still mesh (RF_CLUSTERS_SCENE, default the Stanford dragon): the leaf
// limit L and the subtree option against the triangle build, BVH8, with the
// per-frame stages timed and the traversal counted (pack tests per ray).
TEST(ClustersBench, DISABLED_LeafProfile) {
    const char* path = std::getenv("RF_CLUSTERS_SCENE");
    const Scene scene = load_scene(path ? path : "/work/shared/scenes/stanford-dragon/dragon_vrip.ply");
    SceneGeometry g = SceneGeometry::build(scene);
    BuildOptions build;
    build.threads = 2;
    build.layout = Layout::Bvh8;
    const auto rays = test::make_rays(g, 200000, 9);
    parallel::with_threads(2, [&] {
        auto t0 = std::chrono::steady_clock::now();
        const ClusterPartition clusters = cluster_scene(scene, g, ClusterOptions{});
        std::printf("%zu triangles, %zu clusters (%.1f each), clustering %.0f ms\n", g.size(), clusters.size(),
                    double(g.size()) / clusters.size(), ms_since(t0));
        Bvh tbvh;
        const double tri_build = best_ms(3, [&] { tbvh = build_bvh_on_cpu(g.triangles, build); });
        auto report = [&](const char* name, const Bvh& bvh, double build_ms, double tri_trace) {
            WideBvh<8> wide;
            const double collapse = best_ms(3, [&] { wide = collapse_bvh<8>(bvh, g.triangles); });
            auto acc = make_wide_bvh_accel(g, bvh, build, 0.0, "bvh8");
            std::vector<Hit> hits(rays.size());
            double trace = 1e30;
            for (int r = 0; r < 5; ++r) trace = std::min(trace, best_ms(1, [&] { acc->intersect(rays, hits); }));
            TraversalTotals t;
            acc->count_traversal(rays, false, t);
            std::printf("%-22s build %6.1f + collapse %6.1f ms | packs %zu (fill %.2f), leaves %zu | trace %.1f ms (%+.1f%%) "
                        "steps/ray %.1f tests/ray %.1f\n",
                        name, build_ms, collapse, wide.packs.size(), double(g.size()) / (4.0 * wide.packs.size()),
                        wide.leaf_count, trace, tri_trace > 0 ? 100.0 * (trace / tri_trace - 1.0) : 0.0,
                        double(t.steps) / t.rays, double(t.prim_tests) / t.rays);
            return trace;
        };
        const double tri_trace = report("triangles", tbvh, tri_build, 0.0);
        const BuildOptions box = cluster_box_build_options(build);
        for (const int leaf : {4, 8, 16, 32}) {
            Bvh b;
            const double ms = best_ms(3, [&] { b = build_cluster_bvh(g.triangles, clusters, box, leaf); });
            report(("L=" + std::to_string(leaf)).c_str(), b, ms, tri_trace);
        }
        ClusterPartition sorted = clusters;
        t0 = std::chrono::steady_clock::now();
        ClusterSubtrees sub = build_cluster_subtrees(g.triangles, sorted, build);
        std::printf("subtrees built once in %.0f ms\n", ms_since(t0));
        for (const int leaf : {4, 8, 16}) {
            Bvh b;
            const double refit = best_ms(3, [&] { refit_cluster_subtrees(g.triangles, sorted, sub); });
            const double ms = best_ms(3, [&] { b = build_cluster_bvh(g.triangles, sorted, box, leaf, &sub); });
            std::printf("  subtree refit %.1f ms\n", refit);
            report(("subtrees L=" + std::to_string(leaf)).c_str(), b, refit + ms, tri_trace);
        }
    });
}

}  // namespace
}  // namespace rf

namespace rf {
namespace {

// Prints a hash of the partitions of RF_CLUSTERS_SCENE (default the bunny)
// under the four option sets, and the clustering times: a speed-up of the
// generation must leave the hashes unchanged.
TEST(ClustersBench, DISABLED_PartitionHash) {
    const char* path = std::getenv("RF_CLUSTERS_SCENE");
    const Scene scene = load_scene(path ? path : "/work/shared/scenes/stanford-bunny/bun_zipper.ply");
    const SceneGeometry g = SceneGeometry::build(scene);
    for (const ClusterOptions& o : kAllOptions) {
        const auto t0 = std::chrono::steady_clock::now();
        const ClusterPartition p = parallel::with_threads(2, [&] { return cluster_scene(scene, g, o); });
        const double ms = ms_since(t0);
        uint64_t h = 1469598103934665603ull;
        auto mix = [&](uint64_t x) { h = (h ^ x) * 1099511628211ull; };
        for (uint32_t x : p.first) mix(x);
        for (uint32_t x : p.triangles) mix(x);
        for (uint64_t x : p.vertex_refs) mix(x);
        std::printf("%-12s %zu clusters, hash %016llx, %.0f ms\n", name_of(o).c_str(), p.size(),
                    static_cast<unsigned long long>(h), ms);
    }
}

}  // namespace
}  // namespace rf
