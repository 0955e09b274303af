// The figures the bench reads from the device beside its timings: each trace
// kernel's registers, local memory and occupancy (rf::gpu_kernel_resources),
// and the trace share of a device path-tracing pass (PassStats::trace_ms).
// Skips with a message when no CUDA device is present (fails with
// RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "gpu_test_device.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"

namespace rf {
namespace {

TEST(GpuBenchFigures, TraceKernelsListTheirResources) {
    RF_REQUIRE_DEVICE();
    const Device device{Device::Kind::Cuda, 0};
    for (GpuKernel kernel : all_gpu_kernels()) {
        const std::vector<GpuKernelResources> launches = gpu_kernel_resources(kernel, device);
        if (kernel == GpuKernel::CwbvhFma && launches.empty()) continue;  // its launches are not listed yet
        ASSERT_EQ(launches.size(), 2u) << to_string(kernel) << ": closest and any hit";
        for (const GpuKernelResources& r : launches) {
            EXPECT_NE(r.kernel.find(to_string(kernel)), std::string::npos) << r.kernel;
            EXPECT_GT(r.registers, 0) << r.kernel;
            EXPECT_LE(r.registers, 255) << r.kernel;
            EXPECT_GE(r.max_threads_per_block, r.block_size) << r.kernel;
            EXPECT_GE(r.blocks_per_sm, 1) << r.kernel;
            EXPECT_GT(r.occupancy, 0.0) << r.kernel;
            EXPECT_LE(r.occupancy, 1.0) << r.kernel;
            std::printf("%-40s %3d regs %6zu B local %6zu B shared  %2d blocks/SM  occupancy %.3f\n", r.kernel.c_str(),
                        r.registers, r.local_bytes, r.shared_bytes, r.blocks_per_sm, r.occupancy);
        }
    }
    EXPECT_THROW(gpu_kernel_resources(GpuKernel::AilaLaine, Device{}), Error);
}

TEST(GpuBenchFigures, PathTracingPassReportsItsTraceTime) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("cornell");
    const std::unique_ptr<World> world = make_world(scene, gpu_test::world_on_device(kDefaultGpuKernel));
    RenderOptions options;
    options.width = 128;
    options.height = 96;
    options.max_depth = 4;
    options.integrator = IntegratorKind::Path;
    const std::unique_ptr<Renderer> renderer = make_renderer(*world, world->camera(), options);
    for (int pass = 0; pass < 3; ++pass) {
        renderer->render_pass();
        const PassStats& stats = renderer->last_pass();
        EXPECT_GT(stats.trace_ms, 0.0) << "pass " << pass;
        EXPECT_LT(stats.trace_ms, stats.pass_ms) << "pass " << pass;  // shading, compaction and the host are outside
    }
    // The one-kernel integrators have no separate trace launches.
    options.integrator = IntegratorKind::Whitted;
    const std::unique_ptr<Renderer> whitted = make_renderer(*world, world->camera(), options);
    whitted->render_pass();
    EXPECT_LT(whitted->last_pass().trace_ms, 0.0);
}

}  // namespace
}  // namespace rf
