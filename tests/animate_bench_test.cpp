// `rayforge bench --animate` and `--cluster-table` (bench/harness/animate_bench.h)
// and the Embree dynamic peer: frame ranges, the rows and columns of a run
// on a tiny hand-made animation, the peer against brute force after the
// triangles moved, and the CLI's errors.
#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include "animate_bench.h"
#include "cli_runner.h"
#include "embree_peer.h"
#include "rayforge/core/error.h"
#include "math/random.h"
#include "rayforge/scene/scene.h"

namespace rf {
namespace {

using test::run_cli;

// A UV sphere of radius r at the origin (shared vertices, so clusters apply).
Mesh sphere_mesh(float r, int rings, int segments) {
    Mesh mesh;
    mesh.name = "sphere";
    for (int i = 0; i <= rings; ++i) {
        const float theta = 3.14159265f * float(i) / float(rings);
        for (int j = 0; j < segments; ++j) {
            const float phi = 2.0f * 3.14159265f * float(j) / float(segments);
            mesh.positions.push_back(
                {r * std::sin(theta) * std::cos(phi), r * std::cos(theta), r * std::sin(theta) * std::sin(phi)});
        }
    }
    for (int i = 0; i < rings; ++i)
        for (int j = 0; j < segments; ++j) {
            const uint32_t a = uint32_t(i * segments + j), b = uint32_t(i * segments + (j + 1) % segments);
            const uint32_t c = a + uint32_t(segments), d = b + uint32_t(segments);
            for (uint32_t v : {a, c, b, b, c, d}) mesh.indices.push_back(v);
        }
    mesh.material_ids.assign(mesh.triangle_count(), 0);
    return mesh;
}

// Four spheres flying apart over one second at 8 frames per second (9 frames),
// one instance per sphere, each under its own keyframed node.
bench::LoadedScene flying_spheres() {
    bench::LoadedScene loaded;
    loaded.spec.name = "flying-spheres";
    Scene& scene = loaded.scene;
    scene.meshes.push_back(sphere_mesh(0.5f, 8, 12));
    Animation& anim = scene.animation;
    anim.start = 0.0f;
    anim.end = 1.0f;
    anim.frames_per_second = 8.0f;
    for (uint32_t i = 0; i < 4; ++i) {
        const Vec3f from{float(i % 2) * 1.1f, float(i / 2) * 1.1f, 0.0f};
        const Vec3f to = from * 3.0f + Vec3f{0.0f, 0.0f, float(i)};
        Instance instance;
        instance.mesh = 0;
        instance.transform = Affine3f::translation(from);
        scene.instances.push_back(instance);
        AnimatedNode node;
        node.name = "sphere" + std::to_string(i);
        node.translation = from;
        node.translation_track.interpolation = Interpolation::Linear;
        node.translation_track.width = 3;
        node.translation_track.times = {0.0f, 1.0f};
        node.translation_track.values = {from.x, from.y, from.z, to.x, to.y, to.z};
        anim.nodes.push_back(node);
        anim.instances.push_back({i, i, Affine3f::identity()});
    }
    scene.camera = Camera{};
    scene.camera->eye = {1.5f, 1.5f, 12.0f};
    scene.camera->target = {1.5f, 1.5f, 0.0f};
    scene.finalize();
    loaded.geometry = SceneGeometry::build(scene);
    return loaded;
}

bench::AnimateConfig small_config() {
    bench::AnimateConfig config;
    config.width = 48;
    config.height = 36;
    config.diffuse_rays = 4000;
    config.threads = 2;
    config.progress = false;
    config.frames = {0, 3, 1};
    return config;
}

TEST(AnimateBench, FrameRangesParseAndPlayBackwards) {
    const bench::FrameRange r = bench::parse_frame_range("2:10:4");
    EXPECT_EQ(r.first, 2);
    EXPECT_EQ(r.last, 10);
    EXPECT_EQ(r.step, 4);
    EXPECT_EQ(bench::parse_frame_range("0:5").step, 1);
    for (const char* bad : {"", "3", "5:2", "-1:3", "0:3:0", "a:b", "0:3:1:2", "1:2x"})
        EXPECT_THROW(bench::parse_frame_range(bad), Error) << bad;
    EXPECT_EQ(bench::frame_sequence({2, 10, 4}, 100, false), (std::vector<int>{2, 6, 10}));
    EXPECT_EQ(bench::frame_sequence({0, -1, 1}, 4, false), (std::vector<int>{0, 1, 2, 3}));
    EXPECT_EQ(bench::frame_sequence({0, 50, 1}, 3, false), (std::vector<int>{0, 1, 2}));  // clamped to the animation
    // Garanzha 2014's 100 -> 1 -> 100, in small.
    EXPECT_EQ(bench::frame_sequence({0, 2, 1}, 10, true), (std::vector<int>{0, 1, 2, 1, 0, 1, 2}));
}

// The peer refits or rebuilds over moved triangles and then finds what brute force finds.
TEST(AnimateBench, EmbreeDynamicPeerFollowsTheTriangles) {
    if (!bench::embree_available()) GTEST_SKIP() << "rayforge built without Embree";
    bench::LoadedScene loaded = flying_spheres();
    SceneGeometry& geometry = loaded.geometry;
    std::vector<std::unique_ptr<bench::EmbreeDynamicPeer>> peers;
    for (bench::EmbreeUpdate u : bench::kAllEmbreeUpdates)
        peers.push_back(std::make_unique<bench::EmbreeDynamicPeer>(geometry, u, 2));
    for (Triangle& t : geometry.triangles)  // every triangle moves its own way
        for (Vec3f* v : {&t.v0, &t.v1, &t.v2}) *v = *v * 1.5f + Vec3f{0.3f, -0.2f, 0.1f};
    geometry.bounds = Box3f{};
    for (const Triangle& t : geometry.triangles) geometry.bounds.extend(t.bounds());
    BuildOptions brute;
    brute.structure = Structure::BruteForce;
    const std::unique_ptr<Accel> reference = build_accel(geometry, brute);
    std::vector<Ray> rays;
    RandomStream random(7, 0, 1);
    for (int i = 0; i < 2000; ++i) {
        const Vec2f a = random.next2(), b = random.next2();
        Ray ray;
        const Vec3f c = geometry.bounds.center(), e = geometry.bounds.extent();
        ray.org = {c.x + 1.2f * e.x * (a.x - 0.5f), c.y + 1.2f * e.y * (a.y - 0.5f), 20.0f};
        ray.dir = normalize(Vec3f{0.3f * (b.x - 0.5f), 0.3f * (b.y - 0.5f), -1.0f});
        rays.push_back(ray);
    }
    std::vector<Hit> expected(rays.size());
    reference->intersect(rays, expected);
    size_t found = 0;
    for (const Hit& h : expected) found += h.found() ? 1 : 0;
    ASSERT_GT(found, 300u);  // the rays see the moved spheres
    for (const auto& peer : peers) {
        EXPECT_GE(peer->update(geometry), 0.0);
        std::vector<Hit> hits(rays.size());
        peer->intersect(rays, hits);
        std::vector<uint8_t> occluded(rays.size());
        peer->occluded(rays, occluded);
        size_t same = 0, same_any = 0;
        for (size_t i = 0; i < rays.size(); ++i) {
            same += hits[i].prim == expected[i].prim ? 1 : 0;
            same_any += (occluded[i] != 0) == expected[i].found() ? 1 : 0;
        }
        EXPECT_GE(double(same) / double(rays.size()), 0.995) << bench::embree_update_name(peer->mode());
        EXPECT_GE(double(same_any) / double(rays.size()), 0.995) << bench::embree_update_name(peer->mode());
    }
    SceneGeometry fewer = geometry;
    fewer.triangles.pop_back();
    EXPECT_THROW(peers.front()->update(fewer), Error);
}

TEST(AnimateBench, EveryFrameHasEveryMethodSetAndPeer) {
    bench::LoadedScene loaded = flying_spheres();
    ASSERT_EQ(loaded.scene.animation.frame_count(), 9);
    const bench::AnimateConfig config = small_config();
    std::ostringstream log;
    const bench::AnimateResult result = bench::run_animate_bench(loaded, config, log);
    EXPECT_EQ(result.build_frame, 0);
    ASSERT_EQ(result.frames.size(), 3u);  // frames 1, 2, 3 after building at 0
    ASSERT_EQ(result.methods.size(), 5u);
    // The three peers are always columns; without Embree each says why it is missing.
    ASSERT_EQ(result.embree.size(), 3u);
    for (const bench::PeerColumn& c : result.embree) {
        EXPECT_EQ(c.ok, bench::embree_available());
        if (!c.ok) EXPECT_FALSE(c.error.empty());
    }
    for (const bench::MethodColumn& c : result.methods)
        if (!c.ok) {
            EXPECT_FALSE(c.error.empty()) << to_string(c.method);  // the "n/a (reason)" row
        }
    const bool refit_built = result.methods[0].ok;
    for (size_t i = 0; i < result.frames.size(); ++i) {
        const bench::AnimateFrame& f = result.frames[i];
        EXPECT_EQ(f.frame, int(i) + 1);
        ASSERT_EQ(f.rays.size(), 3u);
        EXPECT_GT(f.rays[0], 0u);
        EXPECT_LE(f.rays[2], config.diffuse_rays);
        EXPECT_GT(f.rays[2], config.diffuse_rays / 2);  // the diffuse view was sized for it
        EXPECT_GT(f.rebuild_sah, 1.0);
        ASSERT_EQ(f.methods.size(), 5u);
        for (const bench::MethodFrame& m : f.methods) {
            if (!m.ok) continue;
            ASSERT_EQ(m.traces.trace_ms.size(), 3u);
            EXPECT_GE(m.traces.agreement, 0.999);  // an updated tree answers like the rebuilt one
        }
        if (refit_built) {
            EXPECT_TRUE(f.methods[0].ok) << f.methods[0].error;
        }
        ASSERT_EQ(f.embree.size(), result.embree.size());
        for (const bench::PeerFrame& p : f.embree) {
            ASSERT_EQ(p.ok, bench::embree_available()) << p.error;
            if (p.ok) EXPECT_GE(p.traces.agreement, 0.99);
        }
    }
    std::ostringstream out;
    bench::print_animate_tables(out, result);
    const std::string text = out.str();
    for (const char* expected : {"== flying-spheres", "-- refit", "-- adapt", "-- rebuild", "-- clusters",
                                 "-- two-level", "averages over 3 frames", "rebuild (full)", "primary", "shadow",
                                 "diffuse"})
        EXPECT_NE(text.find(expected), std::string::npos) << expected << "\n" << text;
    if (bench::embree_available()) {
        for (const char* expected : {"embree refit", "embree low", "embree medium", "vs refit"})
            EXPECT_NE(text.find(expected), std::string::npos) << expected;
    }
}

TEST(AnimateBench, BackwardsPlayKeepsMethodsCorrect) {
    bench::LoadedScene loaded = flying_spheres();
    bench::AnimateConfig config = small_config();
    config.methods = {UpdateMethod::Refit, UpdateMethod::Adapt};
    config.embree.clear();
    config.ray_sets = {bench::RaySetKind::Primary};
    config.frames = {0, 8, 4};
    config.backwards = true;
    std::ostringstream log;
    const bench::AnimateResult result = bench::run_animate_bench(loaded, config, log);
    std::vector<int> played;
    for (const bench::AnimateFrame& f : result.frames) {
        played.push_back(f.frame);
        for (const bench::MethodFrame& m : f.methods)
            if (m.ok) {
                EXPECT_GE(m.traces.agreement, 0.999) << f.frame;
            }
    }
    EXPECT_EQ(played, (std::vector<int>{4, 8, 4, 0, 4, 8}));
}

// Before the keys start nothing moves: the updated trees still report their cost.
TEST(AnimateBench, FramesWithoutMotionKeepTheirSahCost) {
    bench::LoadedScene loaded = flying_spheres();
    for (AnimatedNode& node : loaded.scene.animation.nodes) node.translation_track.times = {0.5f, 1.0f};
    bench::AnimateConfig config = small_config();
    config.methods = {UpdateMethod::Refit, UpdateMethod::Adapt, UpdateMethod::Rebuild};
    config.embree.clear();
    config.ray_sets = {bench::RaySetKind::Primary};
    config.frames = {0, 2, 1};
    std::ostringstream log;
    const bench::AnimateResult result = bench::run_animate_bench(loaded, config, log);
    for (const bench::AnimateFrame& f : result.frames)
        for (const bench::MethodFrame& m : f.methods) {
            if (!m.ok) continue;
            EXPECT_GT(m.stats.sah_cost, 1.0) << f.frame;
            EXPECT_NEAR(m.stats.sah_cost, f.rebuild_sah, 0.5 * f.rebuild_sah) << f.frame;
        }
}

TEST(AnimateBench, UnavailableMethodsPrintTheirReason) {
    bench::AnimateResult result;
    result.scene = "hand-made";
    result.ray_sets = {bench::RaySetKind::Primary};
    result.methods.push_back({UpdateMethod::Clusters, false, "not implemented yet", 0.0});
    bench::AnimateFrame frame;
    frame.frame = 1;
    frame.rays = {100};
    frame.rebuild_ms = 2.0;
    frame.rebuild_trace_ms = {1.0};
    frame.methods.push_back({});
    result.frames.push_back(frame);
    std::ostringstream out;
    bench::print_animate_tables(out, result);
    EXPECT_NE(out.str().find("-- clusters: n/a (not implemented yet)"), std::string::npos) << out.str();
}

TEST(AnimateBench, StillScenesAreRefused) {
    bench::LoadedScene loaded = flying_spheres();
    loaded.scene.animation = Animation{};
    std::ostringstream log;
    EXPECT_THROW(bench::run_animate_bench(loaded, small_config(), log), Error);
}

TEST(AnimateBench, ClusterTableHasARowPerSizeAndHeuristic) {
    bench::LoadedScene loaded = flying_spheres();
    bench::ClusterTableConfig config;
    config.sizes = {0, 10, 50};
    config.width = 32;
    config.height = 24;
    config.threads = 2;
    config.repetitions = 1;
    config.progress = false;
    std::ostringstream log;
    const bench::ClusterTable table = bench::run_cluster_table(loaded, config, log);
    ASSERT_EQ(table.rows.size(), 6u);  // 0, then Acc and Naive at 10 and 50, Acc with subtrees at 50
    EXPECT_TRUE(table.rows[5].subtrees);
    EXPECT_EQ(table.rows[5].clusters, table.rows[3].clusters);  // the same partition as Acc 50/50
    EXPECT_EQ(table.rows[4].clusters, table.rows[3].clusters);  // Naive merging stops at Acc's count
    EXPECT_TRUE(table.rows[0].ok);
    EXPECT_EQ(table.rows[0].clusters, table.triangles);
    EXPECT_GT(table.primary_rays, 0u);
    EXPECT_GT(table.diffuse_rays, 0u);
    for (const bench::ClusterRow& row : table.rows) {
        if (!row.ok) {
            EXPECT_FALSE(row.error.empty());
            continue;
        }
        EXPECT_GE(row.agreement, 0.999) << row.size;
        if (row.clusters > 0) {
            EXPECT_LE(row.clusters, table.triangles);
        }
        EXPECT_GT(row.trace_ratio, 0.0) << row.size;
        EXPECT_GT(row.steps_per_ray, 0.0) << row.size;  // the BVH8 layouts count their work
        EXPECT_GT(row.tests_per_ray, 0.0) << row.size;
    }
    EXPECT_EQ(table.rows[0].trace_ratio, 1.0);
    // Leaves of up to 32 triangles test more triangles a ray than leaves of up to 4.
    EXPECT_GT(table.rows[3].tests_per_ray, table.rows[0].tests_per_ray);
    std::ostringstream out;
    bench::print_cluster_tables(out, {table}, 2);
    for (const char* expected : {"0 (triangles)", "10/10", "50/50", "acc", "naive", "acc+sub", "clustering ms", "tests/ray"})
        EXPECT_NE(out.str().find(expected), std::string::npos) << expected << "\n" << out.str();
}

TEST(AnimateBench, CliOptionsAreChecked) {
    EXPECT_NE(run_cli("bench --help").out.find("--animate"), std::string::npos);
    test::CliResult r = run_cli("bench --animate --frames 5:2 --scene builtin:cube");
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("--frames"), std::string::npos) << r.err;
    r = run_cli("bench --animate --update warp --scene builtin:cube");
    EXPECT_EQ(r.exit_code, 1);
    r = run_cli("bench --animate --embree high --scene builtin:cube");
    EXPECT_EQ(r.exit_code, 1);
    r = run_cli("bench --animate --scene builtin:cube -q");  // a still scene
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("no animation"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace rf
