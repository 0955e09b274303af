// Worlds on a CUDA device: an animated world moved with World::set_time
// renders, with one renderer made once and never told, what a renderer made
// fresh for each frame renders (the device structure a rebuild replaces, a
// refit changes in place, or a two-level update copies, is read by the
// renderer at the start of each pass), and what the CPU renders of the
// same frame (within the FMA tolerance of the renderer tests). Skips with a
// message when no CUDA device is present (fails with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "gpu_test_device.h"
#include "rayforge/core/error.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"

namespace rf {
namespace {

double share_within(const Image& a, const Image& b, float tol) {
    size_t close = 0;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        const Vec3f d = a.pixels[i] - b.pixels[i];
        close += std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)}) <= tol;
    }
    return double(close) / double(a.pixels.size());
}

struct DeviceMethod {
    const char* name;
    UpdateMethod method;
    GpuKernel kernel;
    Builder builder;
};

TEST(GpuWorld, AnimatedWorldRendersAsFreshRenderersPerFrame) {
    RF_REQUIRE_DEVICE();
    const DeviceMethod methods[] = {
        {"refit cwbvh", UpdateMethod::Refit, GpuKernel::Cwbvh, Builder::Hlbvh2},
        {"refit bvh2", UpdateMethod::Refit, GpuKernel::Bvh2, Builder::BinnedSah},
        {"rebuild hlbvh2 cwbvh", UpdateMethod::Rebuild, GpuKernel::Cwbvh, Builder::Hlbvh2},
        {"two-level", UpdateMethod::TwoLevel, GpuKernel::Bvh2, Builder::BinnedSah},
    };
    for (const char* scene : {"builtin:explode@30k", "builtin:nbody@30k"}) {
        for (const DeviceMethod& m : methods) {
            SCOPED_TRACE(std::string(scene) + ", " + m.name);
            WorldOptions options = gpu_test::world_on_device(m.kernel);
            options.build.builder = m.builder;
            options.update.method = m.method;
            const auto world = open_world(scene, options);
            const auto on_cpu = open_world(scene);
            RenderOptions o;
            o.width = 64;
            o.height = 48;
            o.integrator = IntegratorKind::Normals;
            const Camera camera = world->camera();
            const auto renderer = make_renderer(*world, camera, o);
            EXPECT_EQ(renderer->device(), world->device());
            for (int frame : {0, 30, 99, 1}) {
                const float t = world->time_range().frame_time(frame);
                world->set_time(t);
                render_progressive(*renderer);
                const auto fresh = make_renderer(*world, camera, o);
                render_progressive(*fresh);
                EXPECT_EQ(renderer->image().pixels, fresh->image().pixels) << "frame " << frame;
                on_cpu->set_time(t);
                EXPECT_GE(share_within(render(*on_cpu, camera, o), renderer->image(), 1e-3f), 0.99) << "frame " << frame;
            }
            EXPECT_EQ(world->stats().update_method, to_string(m.method));
        }
    }
}

TEST(GpuWorld, WhatTheDeviceCannotDoIsOneLine) {
    RF_REQUIRE_DEVICE();
    WorldOptions adapt = gpu_test::world_on_device(GpuKernel::Cwbvh);
    adapt.update.method = UpdateMethod::Adapt;
    try {
        (void)open_world("builtin:nbody@3k", adapt);
        ADD_FAILURE() << "adapt accepted on the device";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("CPU only"), std::string::npos) << e.what();
    }
    // The scene's own method (none here) falls back to the default; a paged file is refused.
    const auto world = open_world("builtin:nbody@3k", gpu_test::world_on_device(GpuKernel::Cwbvh));
    EXPECT_EQ(world->commit().update_method, to_string(kDefaultUpdateMethod));
    EXPECT_TRUE(world->accel().device().is_cuda());
}

}  // namespace
}  // namespace rf
