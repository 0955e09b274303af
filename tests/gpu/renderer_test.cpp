// The device renderer against the CPU renderer: Whitted, normals and AO
// images equal within floating-point tolerance (same per-sample code, same
// random streams; only FMA contraction differs between the compilers), path
// traced images with the same mean within noise bounds, ray sorting that
// changes nothing, a white furnace that renders 1, and AOVs; all through
// rf::make_renderer with a CUDA device. Skips with a message when no CUDA
// device is present (fails with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "rayforge/accel/accel.h"
#include "gpu_test_device.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/core/error.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"

namespace rf {
namespace {

// A renderer of `scene` on cuda:0 over a CWBVH built there; `world` keeps the world alive.
std::unique_ptr<Renderer> device_renderer(const Scene& scene, const RenderOptions& o, std::unique_ptr<World>& world) {
    world = make_world(scene, gpu_test::world_on_device(GpuKernel::Cwbvh));
    return make_renderer(*world, world->camera(), o);
}

struct Rendered {
    Image cpu, gpu;
    RenderStats cpu_stats, gpu_stats;
};

Rendered render_both(const std::string& scene_name, const RenderOptions& options, GpuKernel kernel) {
    const auto on_cpu = open_world("builtin:" + scene_name);
    const auto cpu = make_renderer(*on_cpu, on_cpu->camera(), options);
    render_progressive(*cpu);
    const auto on_device = open_world("builtin:" + scene_name, gpu_test::world_on_device(kernel));
    const auto gpu = make_renderer(*on_device, on_device->camera(), options);
    render_progressive(*gpu);
    EXPECT_EQ(gpu->passes(), options.spp);
    return {cpu->image(), gpu->image(), cpu->stats(), gpu->stats()};
}

// Share of pixels (all channels) within `tol` of each other, and the largest difference.
double share_within(const Image& a, const Image& b, float tol, float& worst) {
    size_t close = 0;
    worst = 0.0f;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        const Vec3f d = a.pixels[i] - b.pixels[i];
        const float m = std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)});
        worst = std::max(worst, m);
        close += m <= tol;
    }
    return double(close) / double(a.pixels.size());
}

TEST(GpuRenderer, WhittedNormalsAndAoMatchTheCpu) {
    RF_REQUIRE_DEVICE();
    for (IntegratorKind integrator : {IntegratorKind::Whitted, IntegratorKind::Normals, IntegratorKind::AmbientOcclusion})
        for (GpuKernel kernel : {GpuKernel::Cwbvh, GpuKernel::AilaLaine, GpuKernel::KdShortStack, GpuKernel::Grid}) {
            SCOPED_TRACE(integrator_name(integrator) + " / " + to_string(kernel));
            RenderOptions o;
            o.width = 96;
            o.height = 72;
            o.spp = integrator == IntegratorKind::AmbientOcclusion ? 4 : 1;
            o.integrator = integrator;
            const Rendered r = render_both("cornell", o, kernel);
            float worst = 0.0f;
            // A ray grazing an edge may go either way under a different rounding: a few pixels may differ.
            EXPECT_GE(share_within(r.cpu, r.gpu, 1e-3f, worst), 0.995) << "worst " << worst;
            // The same queries, counted the same way (a grazing ray may spawn a ray more or less).
            const auto near = [](uint64_t a, uint64_t b) { return double(a > b ? a - b : b - a) <= 0.005 * double(std::max(a, b)); };
            EXPECT_GT(r.gpu_stats.closest_rays, 0u);
            EXPECT_TRUE(near(r.cpu_stats.closest_rays, r.gpu_stats.closest_rays))
                << r.cpu_stats.closest_rays << " vs " << r.gpu_stats.closest_rays;
            EXPECT_TRUE(near(r.cpu_stats.shadow_rays, r.gpu_stats.shadow_rays))
                << r.cpu_stats.shadow_rays << " vs " << r.gpu_stats.shadow_rays;
        }
}

TEST(GpuRenderer, PathTracedMeanAgreesWithTheCpu) {
    RF_REQUIRE_DEVICE();
    for (const char* scene : {"cornell", "material-spheres"}) {
        SCOPED_TRACE(scene);
        RenderOptions o;
        o.width = 64;
        o.height = 48;
        o.spp = 32;
        o.integrator = IntegratorKind::Path;
        o.max_depth = 6;
        const Rendered r = render_both(scene, o, GpuKernel::Cwbvh);
        // Paired per-pixel differences: their mean must be 0 within 5 standard errors.
        for (int c = 0; c < 3; ++c) {
            double sum = 0.0, sum2 = 0.0;
            const size_t n = r.cpu.pixels.size();
            for (size_t i = 0; i < n; ++i) {
                const double d = double(r.gpu.pixels[i][c]) - double(r.cpu.pixels[i][c]);
                sum += d;
                sum2 += d * d;
            }
            const double mean = sum / double(n);
            const double stderr_mean = std::sqrt(std::max(0.0, sum2 / double(n) - mean * mean) / double(n));
            EXPECT_LE(std::fabs(mean), 5.0 * stderr_mean + 1e-6) << "channel " << c;
        }
        float worst = 0.0f;
        // Same random streams and stage code: most pixels are the CPU's exactly.
        EXPECT_GE(share_within(r.cpu, r.gpu, 1e-3f, worst), 0.9);
    }
}

TEST(GpuRenderer, RaySortingChangesNothing) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("cornell");
    RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.spp = 4;
    o.integrator = IntegratorKind::Path;
    std::unique_ptr<World> world_a, world_b;
    const auto plain = device_renderer(scene, o, world_a);
    render_progressive(*plain);
    o.sort_rays = true;
    const auto sorted = device_renderer(scene, o, world_b);
    render_progressive(*sorted);
    const Image a = plain->image(), b = sorted->image();
    // Sorting only permutes independent paths. A path's hits do not depend on
    // its warp except on an exact tie between two triangles (a shared edge),
    // where CWBVH postponement may pick the other one: allow 0.1 % of pixels.
    size_t differing = 0;
    for (size_t i = 0; i < a.pixels.size(); ++i)
        differing += a.pixels[i].x != b.pixels[i].x || a.pixels[i].y != b.pixels[i].y || a.pixels[i].z != b.pixels[i].z;
    EXPECT_LE(differing, a.pixels.size() / 1000) << differing << " of " << a.pixels.size() << " pixels differ";
    ASSERT_FALSE(sorted->last_pass().waves.empty());
    EXPECT_EQ(sorted->last_pass().waves[0].paths, uint64_t(64 * 48));
}

TEST(GpuRenderer, WhiteFurnaceRendersOne) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("furnace");
    RenderOptions o;
    o.width = 32;
    o.height = 32;
    o.spp = 64;
    o.integrator = IntegratorKind::Path;
    o.max_depth = 64;
    o.rr_depth = 64;
    std::unique_ptr<World> world;
    const auto gpu = device_renderer(scene, o, world);
    render_progressive(*gpu);
    const Image image = gpu->image();
    double sum = 0.0;
    for (const Vec3f& p : image.pixels) sum += p.x + p.y + p.z;
    EXPECT_NEAR(sum / (3.0 * double(image.pixels.size())), 1.0, 0.01);
}

TEST(GpuRenderer, AovsAndCallbacks) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("cornell");
    RenderOptions o;
    o.width = 32;
    o.height = 24;
    o.spp = 10;
    o.integrator = IntegratorKind::Path;
    o.aovs = true;
    std::unique_ptr<World> world;
    const auto gpu = device_renderer(scene, o, world);
    int calls = 0;
    render_progressive(*gpu, [&](const Renderer& r) { return ++calls < 3 && r.passes() > 0; });
    EXPECT_EQ(calls, 3);
    EXPECT_EQ(gpu->passes(), 3);
    EXPECT_EQ(gpu->albedo().pixels.size(), size_t(32 * 24));
    EXPECT_GT(gpu->depth().pixels[size_t(12 * 32 + 16)].x, 0.0f);  // the centre sees the box
    // A camera move restarts; the device cannot record a pass.
    gpu->set_camera(scene.camera_or_default());
    EXPECT_EQ(gpu->passes(), 0);
    std::vector<TracedRay> rays;
    EXPECT_THROW(gpu->render_pass_recorded(rays), Error);
}

}  // namespace
}  // namespace rf
