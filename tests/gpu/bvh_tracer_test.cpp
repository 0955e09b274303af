// GPU traversal of the reference BVH must answer exactly like the CPU: same
// code (trace/*.h), same rays. Skips with a message when no device is present
// (fails with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "accel/bvh/builders/binned_sah.h"
#include "gpu_test_device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "trace/bvh_traversal.h"

namespace rf {
namespace {

std::vector<Ray> random_rays(const Box3f& bounds, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const Vec3f e = bounds.extent();
    std::vector<Ray> rays(count);
    for (size_t i = 0; i < count; ++i) {
        Ray& r = rays[i];
        r.org = bounds.lo + Vec3f{u(rng) * e.x, u(rng) * e.y, u(rng) * e.z};
        Vec3f target = bounds.lo + Vec3f{u(rng) * e.x, u(rng) * e.y, u(rng) * e.z};
        r.dir = normalize(target - r.org + Vec3f{1e-3f, 0, 0});
        r.tmin = 0.0f;
        r.tmax = (i & 1) ? kInfinity : 0.5f * length(e);  // both kinds of tmax
    }
    return rays;
}

TEST(GpuBvhTracer, ListsDevicesWithoutThrowing) {
    const DeviceListing listing = list_cuda_devices();
    // No device is always explained, in the runtime's words.
    if (listing.devices.empty()) EXPECT_FALSE(listing.error.empty());
    RF_REQUIRE_DEVICE();
    EXPECT_FALSE(listing.devices[0].name.empty());
    EXPECT_GT(listing.devices[0].total_memory, 0u);
}

TEST(GpuBvhTracer, ClosestAndAnyHitMatchCpu) {
    RF_REQUIRE_DEVICE();
    Scene scene = make_builtin_scene("spheres");
    SceneGeometry geometry = SceneGeometry::build(scene);
    Bvh bvh = build_binned_sah(geometry.triangles, BvhBuildConfig{}, BinnedSahOptions{});
    BvhView cpu_view{bvh.nodes.data(), bvh.prim_indices.data(), geometry.triangles.data(), uint32_t(bvh.nodes.size())};

    std::vector<Ray> rays = random_rays(geometry.bounds, 200000, 7);
    // The same binned tree on the device (binned SAH has no device builder:
    // built on the host, uploaded), traced one thread per ray.
    const auto tracer = build_accel(geometry, gpu_test::on_device(GpuKernel::Bvh2));
    std::vector<Hit> gpu_hits(rays.size());
    std::vector<uint8_t> gpu_occluded(rays.size());
    tracer->intersect(rays, gpu_hits);
    tracer->occluded(rays, gpu_occluded);

    size_t mismatches = 0, hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        Hit cpu = bvh_intersect(cpu_view, rays[i]);
        hits += cpu.found();
        if (cpu.found() != gpu_hits[i].found()) { ++mismatches; continue; }
        if (cpu.found()) {
            // Same code, same inputs; only FMA contraction may differ between compilers.
            if (cpu.prim != gpu_hits[i].prim && std::fabs(cpu.t - gpu_hits[i].t) > 1e-5f * cpu.t) ++mismatches;
            else EXPECT_NEAR(cpu.t, gpu_hits[i].t, 1e-5f * cpu.t);
        }
        EXPECT_EQ(bool(gpu_occluded[i]), cpu.found()) << "ray " << i;
    }
    EXPECT_GT(hits, rays.size() / 10);
    EXPECT_EQ(mismatches, 0u);
}

TEST(GpuBvhTracer, RejectsMismatchedSpans) {
    RF_REQUIRE_DEVICE();
    Scene scene = make_builtin_scene("cornell");
    SceneGeometry geometry = SceneGeometry::build(scene);
    const auto tracer = build_accel(geometry, gpu_test::on_device(GpuKernel::Bvh2));
    std::vector<Ray> rays(4);
    std::vector<Hit> hits(3);
    EXPECT_THROW(tracer->intersect(rays, hits), Error);
}

}  // namespace
}  // namespace rf
