// Dynamic structures on the device (backend/cuda/device_dynamic_accel.cpp)
// through rf::build_dynamic_accel: refit (bvh2 traced in place; node pairs
// and CWBVH converted again), rebuild with hlbvh2 on the device, and
// two-level, each stepped through an animation forwards and back (frame 0
// -> 99 -> 1) and answering like a CPU BVH built from scratch at every
// frame; the device renderer over a two-level structure renders what the
// CPU renders; CPU-only methods are refused in one line. Skips without a
// device (fails with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "gpu_test_device.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/world.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"

namespace rf {
namespace {

std::vector<Ray> random_rays(const SceneGeometry& g, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays(count);
    for (Ray& r : rays) {
        r.org = g.bounds.lo + Vec3f(unit(rng), unit(rng), unit(rng)) * g.bounds.extent();
        r.dir = normalize(Vec3f(unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) - 0.5f) + Vec3f(1e-3f, 0, 0));
    }
    return rays;
}

// Share of rays whose closest hit (t within 1e-4 relative) or occlusion differs from a fresh CPU build's.
double disagreement(const Accel& accel, const SceneGeometry& g, uint32_t seed) {
    const auto reference = build_accel(g);
    const std::vector<Ray> rays = random_rays(g, 50000, seed);
    std::vector<Hit> want(rays.size()), got(rays.size());
    std::vector<uint8_t> want_occ(rays.size()), got_occ(rays.size());
    reference->intersect(rays, want);
    reference->occluded(rays, want_occ);
    accel.intersect(rays, got);
    accel.occluded(rays, got_occ);
    size_t differ = 0, found = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        found += want[i].found();
        const bool same_t = !want[i].found() || std::fabs(got[i].t - want[i].t) <= 1e-4f * std::max(1.0f, want[i].t);
        differ += got[i].found() != want[i].found() || !same_t || got_occ[i] != want_occ[i];
    }
    EXPECT_GT(found, rays.size() / 20) << "too few rays hit anything to tell";
    return double(differ) / double(rays.size());
}

struct DeviceMethod {
    std::string name;
    UpdateMethod method;
    GpuKernel kernel;
    Builder builder;
};

TEST(GpuDynamicAccel, EveryDeviceMethodFollowsTheAnimationBothWays) {
    RF_REQUIRE_DEVICE();
    const std::vector<DeviceMethod> methods = {
        {"refit bvh2", UpdateMethod::Refit, GpuKernel::Bvh2, Builder::BinnedSah},
        {"refit aila-laine", UpdateMethod::Refit, GpuKernel::AilaLaine, Builder::Hlbvh2},
        {"refit cwbvh", UpdateMethod::Refit, GpuKernel::Cwbvh, Builder::Hlbvh2},
        {"rebuild hlbvh2 cwbvh", UpdateMethod::Rebuild, GpuKernel::Cwbvh, Builder::Hlbvh2},
        {"two-level", UpdateMethod::TwoLevel, GpuKernel::Bvh2, Builder::BinnedSah},
    };
    for (const char* name : {"builtin:explode@60k", "builtin:nbody@60k", "builtin:cloth@30k"}) {
        for (const DeviceMethod& m : methods) {
            SCOPED_TRACE(std::string(name) + ", " + m.name);
            Scene scene = load_scene(name);
            scene.set_time(scene.animation.frame_time(0));
            SceneGeometry g = SceneGeometry::build(scene);
            BuildOptions build = gpu_test::on_device(m.kernel);
            build.builder = m.builder;
            build.build_on_device = true;
            const auto accel = build_dynamic_accel(scene, g, build, UpdateOptions{m.method, {}, {}});
            EXPECT_TRUE(accel->current().device().is_cuda());
            EXPECT_EQ(accel->method(), m.method);
            for (int frame : {30, 99, 1}) {
                const GeometryChange change = scene.set_time(scene.animation.frame_time(frame));
                g.update(scene, change);
                const UpdateStats u = accel->update(change);
                EXPECT_GT(u.update_ms, 0.0);
                // The compilers contract to FMA differently: a ray grazing an edge may go either way
                // (the renderer tests allow the same); two-level also transforms rays into object space.
                EXPECT_LE(disagreement(accel->current(), g, uint32_t(frame)), m.method == UpdateMethod::TwoLevel ? 2e-3 : 1e-3)
                    << "frame " << frame;
            }
        }
    }
}

TEST(GpuDynamicAccel, TwoLevelRenderMatchesTheCpu) {
    RF_REQUIRE_DEVICE();
    WorldOptions two_level = gpu_test::world_on_device(GpuKernel::Bvh2);
    two_level.update.method = UpdateMethod::TwoLevel;
    const auto device = open_world("builtin:nbody@40k", two_level);
    device->commit();
    const float t = device->time_range().frame_time(50);
    device->set_time(t);
    const auto on_cpu = open_world("builtin:nbody@40k");
    on_cpu->set_time(t);

    RenderOptions o;
    o.width = 96;
    o.height = 72;
    o.spp = 1;
    o.integrator = IntegratorKind::Normals;
    const Camera camera = on_cpu->camera();
    const auto cpu = make_renderer(*on_cpu, camera, o);
    render_progressive(*cpu);
    const auto gpu = make_renderer(*device, camera, o);
    render_progressive(*gpu);
    size_t close = 0;
    const Image a = cpu->image(), b = gpu->image();
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        const Vec3f d = a.pixels[i] - b.pixels[i];
        close += std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)}) <= 1e-3f;
    }
    EXPECT_GE(double(close) / double(a.pixels.size()), 0.995);
}

TEST(GpuDynamicAccel, CpuOnlyMethodsAreRefusedInOneLine) {
    RF_REQUIRE_DEVICE();
    Scene scene = load_scene("builtin:nbody@20k");
    const SceneGeometry g = SceneGeometry::build(scene);
    for (UpdateMethod method : {UpdateMethod::Adapt, UpdateMethod::Clusters}) {
        try {
            (void)build_dynamic_accel(scene, g, gpu_test::on_device(GpuKernel::Cwbvh), UpdateOptions{method, {}, {}});
            ADD_FAILURE() << to_string(method) << " was accepted on the device";
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("CPU only"), std::string::npos) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        }
    }
}

}  // namespace
}  // namespace rf
