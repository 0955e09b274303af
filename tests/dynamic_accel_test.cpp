// build_dynamic_accel: every update method, on a scene with rigidly moving
// instances, a deforming mesh and a hidden instance, answers like brute force
// at several frames, forwards and backwards in time (Garanzha 2014 ch. 2's 100 -> 1 -> 100).
#include <gtest/gtest.h>

#include <cmath>

#include "accel/brute_force.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using test::to_mesh;

// Linear translation + rotation keys for node `node`, sampled at `frames` frames.
AnimatedNode moving_node(int k, int frames) {
    AnimatedNode node;
    node.name = "body" + std::to_string(k);
    node.translation_track.interpolation = Interpolation::Linear;
    node.rotation_track.interpolation = Interpolation::Linear;
    node.rotation_track.width = 4;
    for (int f = 0; f < frames; ++f) {
        const float t = float(f) / 30.0f;
        node.translation_track.times.push_back(t);
        node.rotation_track.times.push_back(t);
        const float a = 0.3f * float(k) + 0.05f * float(f);
        // Bodies start in a heap and fly apart (migrations and explosions both happen).
        const float r = 0.2f + 0.15f * float(f) * float(1 + k % 3);
        for (float v : {r * std::cos(a + float(k)), 0.1f * float(k % 5) + 0.02f * float(f), r * std::sin(a + float(k))})
            node.translation_track.values.push_back(v);
        const float half = 0.5f * (0.2f * float(f) + float(k));
        for (float v : {0.0f, std::sin(half), 0.0f, std::cos(half)}) node.rotation_track.values.push_back(v);
    }
    return node;
}

Scene make_animated_scene(int bodies, int frames) {
    Scene scene;
    scene.materials.push_back(Material{});
    scene.meshes.push_back(to_mesh(test::make_icosphere(2), "ball"));       // rigid bodies
    scene.meshes.push_back(to_mesh(test::make_tessellated_cube(6), "blob"));  // deforming
    for (int k = 0; k < bodies; ++k) {
        Instance inst;
        inst.mesh = 0;
        inst.transform = Affine3f::scale(Vec3f(0.15f));
        scene.instances.push_back(inst);
        scene.animation.nodes.push_back(moving_node(k, frames));
        scene.animation.instances.push_back({uint32_t(k), uint32_t(k), Affine3f::scale(Vec3f(0.15f))});
    }
    scene.instances.push_back({1, Affine3f::translation(Vec3f(0.0f, -1.0f, 0.0f))});
    VertexKeyframes keys;
    keys.mesh = 1;
    const std::vector<Vec3f>& rest = scene.meshes[1].positions;
    for (int f = 0; f < frames; ++f) {
        keys.times.push_back(float(f) / 30.0f);
        std::vector<Vec3f> p = rest;
        for (Vec3f& v : p) v = v * (1.0f + 0.3f * std::sin(0.2f * float(f) + 3.0f * v.x));
        keys.positions.push_back(std::move(p));
    }
    scene.animation.vertex_keyframes.push_back(std::move(keys));
    scene.animation.end = float(frames - 1) / 30.0f;
    scene.finalize();
    return scene;
}

// Hits and any-hit answers equal brute force on the flat triangles. A
// two-level structure tests instances' triangles in object space (the ray
// transformed, not the vertices), so a ray grazing a silhouette exactly at a
// vertex or edge may legitimately go either way: `allowed_misses` of the
// rays may disagree (a hit or not, or the hit behind such a vertex); exact
// methods must agree on every ray.
void expect_brute_force_hits(const Accel& accel, const SceneGeometry& geometry, uint32_t seed, const std::string& where,
                             double allowed_misses = 0.0) {
    const BruteForceAccel reference(geometry);
    const std::vector<Ray> rays = test::make_rays(geometry, 600, seed);
    size_t disagreements = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit expected = reference.intersect(rays[i]);
        const Hit got = accel.intersect(rays[i]);
        const bool same_t = !expected.found() || std::abs(got.t - expected.t) <= 1e-4f * std::max(1.0f, expected.t);
        if (got.found() != expected.found() || !same_t || accel.occluded(rays[i]) != reference.occluded(rays[i])) {
            ++disagreements;
            EXPECT_GT(allowed_misses, 0.0) << where << " ray " << i << ": t " << got.t << " expected " << expected.t;
        }
    }
    EXPECT_LE(double(disagreements), allowed_misses * double(rays.size())) << where;
}

class DynamicAccelMethods : public ::testing::TestWithParam<UpdateMethod> {};

TEST_P(DynamicAccelMethods, HitsEqualBruteForceForwardsAndBackwards) {
    constexpr int kFrames = 24;
    Scene scene = make_animated_scene(16, kFrames);
    scene.set_time(0.0f);
    SceneGeometry geometry = SceneGeometry::build(scene);
    UpdateOptions update;
    update.method = GetParam();
    update.clusters.max_count = 20;
    update.clusters.max_size = 20.0f;
    BuildOptions build;
    build.threads = 2;
    const std::unique_ptr<DynamicAccel> accel = build_dynamic_accel(scene, geometry, build, update);
    EXPECT_EQ(accel->method(), GetParam());
    // 0 -> 23 -> 0 -> 23, checking every 11th step.
    std::vector<int> frames;
    for (int f = 1; f < kFrames; ++f) frames.push_back(f);
    for (int f = kFrames - 2; f >= 0; --f) frames.push_back(f);
    for (int f = 1; f < kFrames; ++f) frames.push_back(f);
    for (size_t k = 0; k < frames.size(); ++k) {
        const GeometryChange change = scene.set_time(scene.animation.frame_time(frames[k]));
        ASSERT_TRUE(change.geometry());
        geometry.update(scene, change);
        const UpdateStats stats = accel->update(change);
        EXPECT_GE(stats.update_ms, 0.0);
        EXPECT_TRUE(std::isfinite(stats.sah_cost));
        if (k % 11 == 0 || k + 1 == frames.size())
            expect_brute_force_hits(*accel, geometry, uint32_t(k), to_string(GetParam()) + " step " + std::to_string(k),
                                    GetParam() == UpdateMethod::TwoLevel ? 0.01 : 0.0);
    }
}

INSTANTIATE_TEST_SUITE_P(AllMethods, DynamicAccelMethods,
                         ::testing::Values(UpdateMethod::Refit, UpdateMethod::Adapt, UpdateMethod::Rebuild,
                                           UpdateMethod::Clusters, UpdateMethod::TwoLevel),
                         [](const auto& info) {
                             std::string name = to_string(info.param);
                             std::erase(name, '-');
                             return name;
                         });

TEST(DynamicAccel, EveryLayoutFollowsAHiddenInstance) {
    Scene scene = make_animated_scene(6, 10);
    scene.animation.nodes[2].visibility.interpolation = Interpolation::Step;
    scene.animation.nodes[2].visibility.width = 1;
    scene.animation.nodes[2].visibility.times = {0.0f, 0.1f};
    scene.animation.nodes[2].visibility.values = {1.0f, 0.0f};
    scene.set_time(0.0f);
    SceneGeometry geometry = SceneGeometry::build(scene);
    for (Layout layout : {Layout::Bvh2, Layout::Bvh4, Layout::Bvh8}) {
        Scene s = scene;
        SceneGeometry g = geometry;
        BuildOptions build;
        build.layout = layout;
        const auto accel = build_dynamic_accel(s, g, build, UpdateOptions{UpdateMethod::Refit, {}, {}});
        const GeometryChange change = s.set_time(0.2f);
        EXPECT_FALSE(s.instances[2].visible);
        g.update(s, change);
        accel->update(change);
        expect_brute_force_hits(*accel, g, 7, to_string(layout));
        const auto two_level = build_dynamic_accel(s, g, build, UpdateOptions{UpdateMethod::TwoLevel, {}, {}});
        expect_brute_force_hits(*two_level, g, 8, "two-level " + to_string(layout), 0.01);
    }
}

TEST(DynamicAccel, OptionErrorsAreOneLine) {
    Scene scene = make_animated_scene(2, 3);
    SceneGeometry geometry = SceneGeometry::build(scene);
    UpdateOptions bad;
    bad.adapt.migrate_threshold = 1.5f;
    try {
        (void)build_dynamic_accel(scene, geometry, {}, bad);
        FAIL() << "expected rf::Error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("dM"), std::string::npos) << e.what();
    }
    BuildOptions grid;
    grid.structure = Structure::Grid;
    EXPECT_THROW((void)build_dynamic_accel(scene, geometry, grid, {}), Error);
    EXPECT_THROW((void)parse_update_method("refit-ish"), Error);
    EXPECT_EQ(parse_update_method("two-level"), UpdateMethod::TwoLevel);
    EXPECT_EQ(to_string(UpdateMethod::Clusters), "clusters");
    EXPECT_FLOAT_EQ(parse_adapt_reading("closing").migrate_threshold, 0.01f);
    EXPECT_FLOAT_EQ(parse_adapt_reading("closing").explode_threshold, 0.05f);
}

// Which methods a CUDA device runs, and that asking one without a usable
// device (or a build without the backend) is one line, not a crash.
TEST(DynamicAccel, DeviceMethodsAndTheirErrors) {
    EXPECT_TRUE(update_runs_on_device(UpdateMethod::Refit));
    EXPECT_TRUE(update_runs_on_device(UpdateMethod::Rebuild));
    EXPECT_TRUE(update_runs_on_device(UpdateMethod::TwoLevel));
    EXPECT_FALSE(update_runs_on_device(UpdateMethod::Adapt));
    EXPECT_FALSE(update_runs_on_device(UpdateMethod::Clusters));
    if (!list_cuda_devices().devices.empty()) GTEST_SKIP() << "a device is present: tests/gpu covers it";
    Scene scene = make_animated_scene(2, 3);
    SceneGeometry geometry = SceneGeometry::build(scene);
    BuildOptions build;
    build.device = Device{Device::Kind::Cuda, 0};
    build.gpu_kernel = GpuKernel::Bvh2;
    for (UpdateMethod method : {UpdateMethod::Refit, UpdateMethod::Rebuild, UpdateMethod::TwoLevel}) {
        try {
            (void)build_dynamic_accel(scene, geometry, build, UpdateOptions{method, {}, {}});
            ADD_FAILURE() << to_string(method) << " built on a device that is not there";
        } catch (const Error& e) {
            EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
        }
    }
}

}  // namespace
}  // namespace rf
