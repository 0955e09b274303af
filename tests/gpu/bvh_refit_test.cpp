// The device refit (backend/cuda/bvh_refit.cu) against the CPU refit
// (accel/bvh/refit.cpp): bit-identical boxes on the common scenes after
// random per-triangle motion, with leaves of 1 and 4 and several builders;
// a tree kept on the device refitted frame after frame (the counters reset
// themselves); hits of the refitted tree equal brute force; empty and
// one-triangle trees; and the kernel's time on a 1M-triangle soup, printed
// beside the CPU refit's. Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "gpu_build_checks.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/refit.h"
#include "backend/cuda/bvh_refit.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gpu_build_test::expect_same_bvh;
using gpu_build_test::NamedScene;

SceneGeometry moved(const SceneGeometry& g, uint32_t seed, float shift) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    SceneGeometry out = g;
    out.bounds = Box3f();
    for (Triangle& t : out.triangles) {
        const Vec3f offset(u(rng) * shift, u(rng) * shift, u(rng) * shift);
        t.v0 = t.v0 + offset;
        t.v1 = t.v1 + offset + Vec3f(u(rng), u(rng), u(rng)) * (0.2f * shift);
        t.v2 = t.v2 + offset;
        out.bounds.extend(t.bounds());
    }
    return out;
}

BuildOptions with_builder(Builder builder, int leaf_size) {
    BuildOptions options;
    options.builder = builder;
    options.max_leaf_size = leaf_size;
    return options;
}

TEST(GpuBvhRefit, SameBoxesAsCpuRefit) {
    RF_REQUIRE_DEVICE();
    std::vector<NamedScene> scenes = gpu_build_test::common_scenes();
    gpu_build_test::append_degenerate_scenes(scenes);
    for (const NamedScene& scene : scenes) {
        for (Builder builder : {Builder::BinnedSah, Builder::Lbvh30}) {
            for (int leaf_size : {1, 4}) {
                const std::string what = scene.name + ", " + to_string(builder) + ", leaves of " + std::to_string(leaf_size);
                const Bvh built = build_bvh_on_cpu(scene.geometry.triangles, with_builder(builder, leaf_size));
                const SceneGeometry g = moved(scene.geometry, 3, 0.5f);
                Bvh cpu = built, gpu = built;
                refit_bvh(cpu, g.triangles);
                const cuda::DeviceRefitTimes times = cuda::refit_bvh_on_device(gpu, g.triangles, 2);
                expect_same_bvh(cpu, gpu, what);
                EXPECT_GE(times.refit_mean_ms, times.refit_ms) << what;
            }
        }
    }
}

TEST(GpuBvhRefit, FrameAfterFrameOnTheDevice) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry start = gpu_build_test::hit_test_soup();
    Bvh cpu = build_bvh_on_cpu(start.triangles, BuildOptions{});
    cuda::DeviceBvhRefit device(cpu);
    EXPECT_EQ(device.arrays().leaf_count, cpu.leaf_count());
    Bvh gpu = cpu;
    for (uint32_t frame = 0; frame < 5; ++frame) {
        // Forwards, then back to frame 1 (Garanzha 2014 ch. 2's 100 -> 1 -> 100).
        const uint32_t t = frame < 3 ? frame : 4 - frame;
        const SceneGeometry g = moved(start, t, 0.4f * float(1 + t));
        refit_bvh(cpu, g.triangles);
        EXPECT_GE(device.refit(g.triangles), 0.0);
        device.download(gpu);
        expect_same_bvh(cpu, gpu, "frame " + std::to_string(frame));
        gpu_build_test::expect_hits_equal_brute_force(g, gpu, "frame " + std::to_string(frame));
    }
    EXPECT_THROW(device.refit(std::span<const Triangle>(start.triangles).first(10)), Error);
}

TEST(GpuBvhRefit, EmptyAndSingleTriangle) {
    RF_REQUIRE_DEVICE();
    Bvh empty;
    EXPECT_NO_THROW(cuda::refit_bvh_on_device(empty, {}));
    cuda::DeviceBvhRefit empty_device(empty);
    EXPECT_NO_THROW(empty_device.refit({}));

    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    Bvh bvh = build_bvh_on_cpu(one.triangles, BuildOptions{});
    const std::vector<Triangle> far{{Vec3f(2, 3, 4), Vec3f(5, 3, 4), Vec3f(2, 7, -1)}};
    cuda::refit_bvh_on_device(bvh, far);
    ASSERT_EQ(bvh.nodes.size(), 1u);
    EXPECT_EQ(bvh.nodes[0].bounds.lo, Vec3f(2, 3, -1));
    EXPECT_EQ(bvh.nodes[0].bounds.hi, Vec3f(5, 7, 4));
    EXPECT_THROW(cuda::refit_bvh_on_device(bvh, far, 0), Error);
}

// Not a check: the numbers for docs/benchmarks.md (1M triangles, LBVH tree
// with leaves of 4; the device's kernel against the CPU refit on this host).
TEST(GpuBvhRefit, KernelTimeOnOneMillionTriangles) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry start = test::make_triangle_soup(1000000, 9, {Vec3f(-100.0f), Vec3f(100.0f)}, 0.5f);
    Bvh cpu = build_bvh_on_cpu(start.triangles, with_builder(Builder::Lbvh30, 4));
    const SceneGeometry g = moved(start, 1, 0.5f);
    Bvh gpu = cpu;
    const cuda::DeviceRefitTimes times = cuda::refit_bvh_on_device(gpu, g.triangles, 20);
    RefitPlan plan = make_refit_plan(cpu);
    double cpu_best = 1e30;
    for (int r = 0; r < 5; ++r) {
        const auto t0 = std::chrono::steady_clock::now();
        refit_bvh(cpu, g.triangles, plan);
        cpu_best = std::min(cpu_best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    expect_same_bvh(cpu, gpu, "1M soup");
    std::printf("refit of %zu nodes: device kernel %.3f ms (mean %.3f), topology upload %.1f ms, download %.1f ms; "
                "CPU refit %.2f ms\n",
                cpu.nodes.size(), times.refit_ms, times.refit_mean_ms, times.upload_ms, times.download_ms, cpu_best);
    RecordProperty("device_refit_ms", std::to_string(times.refit_ms));
    RecordProperty("cpu_refit_ms", std::to_string(cpu_best));
}

}  // namespace
}  // namespace rf
