// Every GPU traversal kernel (rf::GpuKernel) against the CPU: same hits
// (hit or miss, primitive, t within 1e-5 relative) as the brute-force
// reference for camera rays, diffuse bounce rays and random rays; any-hit
// queries agree with closest-hit ones; the resident-ray timing of the bench
// and the instrumented traversal work; error paths give clean rf::Errors.
// Everything through the public API: rf::build_accel on a CUDA device.
// Skips with a message when no CUDA device is present (fails with
// RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "backend/cuda/self_test.h"
#include "gpu_test_device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/camera.h"
#include "trace/aila_laine_fma_traversal.h"

namespace rf {
namespace {

// Camera rays through a jittered 96x72 image, then one cosine-free diffuse
// bounce from every hit (random directions in the facing hemisphere), then
// rays between random points of the scene box: the protocol's primary and
// diffuse sets in small, plus incoherent ones.
std::vector<Ray> test_rays(const Scene& scene, const SceneGeometry& g, const Accel& reference, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const int w = 96, h = 72;
    const CameraFrame camera = CameraFrame::make(scene.camera_or_default(), w, h);
    std::vector<Ray> rays;
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) rays.push_back(camera.generate(x + u(rng), y + u(rng), w, h, 0.5f, 0.5f));
    const size_t primaries = rays.size();
    const float eps = 1e-4f * length(g.bounds.extent());
    for (size_t i = 0; i < primaries; ++i) {
        const Hit hit = reference.intersect(rays[i]);
        if (!hit.found()) continue;
        const Triangle& t = g.triangles[hit.prim];
        Vec3f n = normalize(cross(t.v1 - t.v0, t.v2 - t.v0));
        if (dot(n, rays[i].dir) > 0.0f) n = -n;
        Vec3f d;
        do d = Vec3f(2 * u(rng) - 1, 2 * u(rng) - 1, 2 * u(rng) - 1);
        while (dot(d, d) > 1.0f || dot(d, d) < 1e-4f);
        d = normalize(d);
        if (dot(d, n) < 0.0f) d = -d;
        Ray bounce;
        bounce.org = rays[i].org + rays[i].dir * hit.t + n * eps;
        bounce.dir = d;
        rays.push_back(bounce);
    }
    const Vec3f e = g.bounds.extent();
    for (int i = 0; i < 20000; ++i) {
        Ray r;
        r.org = g.bounds.lo + Vec3f(u(rng) * e.x, u(rng) * e.y, u(rng) * e.z);
        const Vec3f to = g.bounds.lo + Vec3f(u(rng) * e.x, u(rng) * e.y, u(rng) * e.z);
        r.dir = normalize(to - r.org + Vec3f(1e-3f, 0.0f, 0.0f));
        if (i % 3 == 0) r.tmax = 0.25f * length(e);
        rays.push_back(r);
    }
    return rays;
}

void expect_same_hits(const std::vector<Ray>& rays, const std::vector<Hit>& expected, const std::vector<Hit>& got,
                      const std::vector<uint8_t>& occluded, const std::string& what) {
    size_t mismatches = 0, hits = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        hits += expected[i].found();
        bool same = expected[i].found() == got[i].found();
        if (same && expected[i].found()) {
            const float tol = 1e-5f * std::fabs(expected[i].t);
            // Another triangle at the same distance (shared edges) is the same answer.
            same = std::fabs(expected[i].t - got[i].t) <= tol;
        }
        if (bool(occluded[i]) != expected[i].found()) same = false;
        if (!same && ++mismatches <= 5)
            ADD_FAILURE() << what << ": ray " << i << " cpu prim " << expected[i].prim << " t " << expected[i].t
                          << ", gpu prim " << got[i].prim << " t " << got[i].t << " occluded "
                          << int(occluded[i]);
    }
    EXPECT_EQ(mismatches, 0u) << what;
    EXPECT_GT(hits, rays.size() / 10) << what;
}

TEST(GpuDeviceTracer, EveryKernelMatchesBruteForce) {
    RF_REQUIRE_DEVICE();
    for (const char* name : {"cornell", "spheres", "material-spheres"}) {
        const Scene scene = make_builtin_scene(name);
        const SceneGeometry g = SceneGeometry::build(scene);
        const BruteForceAccel brute(g);
        const std::vector<Ray> rays = test_rays(scene, g, brute, 7);
        std::vector<Hit> expected(rays.size());
        brute.intersect(rays, expected);
        for (GpuKernel kernel : all_gpu_kernels()) {
            const std::string what = std::string(name) + " / " + to_string(kernel);
            SCOPED_TRACE(what);
            const auto tracer = build_accel(g, gpu_test::on_device(kernel));
            EXPECT_EQ(tracer->device(), parse_device("cuda:0"));
            std::vector<Hit> hits(rays.size());
            std::vector<uint8_t> occluded(rays.size());
            tracer->intersect(rays, hits);
            tracer->occluded(rays, occluded);
            expect_same_hits(rays, expected, hits, occluded, what);
            EXPECT_GT(tracer->stats().device_bytes, 0u);
            EXPECT_NE(tracer->stats().name.find(to_string(kernel)), std::string::npos);
        }
    }
}

TEST(GpuDeviceTracer, BuildersAndLeafSizesForTheBvhKernels) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("spheres");
    const SceneGeometry g = SceneGeometry::build(scene);
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = test_rays(scene, g, brute, 11);
    std::vector<Hit> expected(rays.size());
    brute.intersect(rays, expected);
    for (Builder builder : {Builder::Sbvh, Builder::Lbvh30, Builder::Hlbvh2, Builder::Ploc})
        for (GpuKernel kernel : {GpuKernel::Bvh2, GpuKernel::AilaLaine, GpuKernel::AilaLaineFma, GpuKernel::Cwbvh,
                                 GpuKernel::CwbvhFma}) {
            const std::string what = to_string(builder) + " / " + to_string(kernel);
            BuildOptions build;
            build.builder = builder;
            build.max_leaf_size = 8;
            const auto tracer = build_accel(g, gpu_test::on_device(kernel, build));
            std::vector<Hit> hits(rays.size());
            std::vector<uint8_t> occluded(rays.size());
            tracer->intersect(rays, hits);
            tracer->occluded(rays, occluded);
            expect_same_hits(rays, expected, hits, occluded, what);
        }
}

TEST(GpuDeviceTracer, ResidentRaysAndCountersMatchTheOneShotPath) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("cornell");
    const SceneGeometry g = SceneGeometry::build(scene);
    const BruteForceAccel brute(g);
    const std::vector<Ray> rays = test_rays(scene, g, brute, 3);
    for (GpuKernel kernel : all_gpu_kernels()) {
        SCOPED_TRACE(to_string(kernel));
        const auto tracer = build_accel(g, gpu_test::on_device(kernel));
        std::vector<Hit> once(rays.size()), resident(rays.size());
        std::vector<uint8_t> no_flags;
        tracer->intersect(rays, once);
        const std::vector<double> runs = tracer->time_traversal(rays, false, 2, resident, no_flags);
        ASSERT_EQ(runs.size(), 2u);
        EXPECT_GT(runs[0], 0.0);
        // Same t; the primitive may differ only on an exact tie (a shared
        // edge), where speculation or postponement can reorder the tests.
        for (size_t i = 0; i < rays.size(); ++i) {
            ASSERT_EQ(once[i].found(), resident[i].found()) << i;
            ASSERT_EQ(once[i].t, resident[i].t) << i;
        }
        TraversalTotals totals;
        EXPECT_TRUE(tracer->count_traversal(rays, false, totals));
        EXPECT_EQ(totals.rays, rays.size());
        EXPECT_GT(totals.steps, totals.rays);
        EXPECT_GT(totals.prim_tests, 0u);
        if (kernel == GpuKernel::Bvh2 || kernel == GpuKernel::AilaLaine || kernel == GpuKernel::AilaLaineFma ||
            kernel == GpuKernel::Cwbvh)
            EXPECT_GT(totals.node_fetches, 0u);  // node fetches, for comparing layouts
    }
}

// aila-laine-fma on the device (persistent warps, dynamic fetch, the FMA box
// test compiled by nvcc) against the same shared traversal on the host over
// the same node pairs: the same answer for every ray, t bit for bit (the
// primitive may differ only on an exact tie, where the warp's speculation can
// reorder the triangle tests); and against aila-laine on the device. Enough
// rays that warps refill many times, a count that is no multiple of 32, and
// rays with zero direction components (the classic-slab fallback).
TEST(GpuDeviceTracer, AilaLaineFmaAnswersLikeTheCpu) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("spheres");
    const SceneGeometry g = SceneGeometry::build(scene);
    const BruteForceAccel brute(g);
    std::vector<Ray> rays = test_rays(scene, g, brute, 29);
    std::mt19937 rng(9);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const Vec3f c = g.bounds.center(), e = g.bounds.extent();
    for (int i = 0; i < 100003; ++i) {
        Ray r;
        r.org = c + Vec3f(u(rng) * e.x, u(rng) * e.y, u(rng) * e.z);
        r.dir = Vec3f(u(rng), u(rng), u(rng));
        if (i % 13 == 0) r.dir[i % 3] = 0.0f;
        if (i % 7 == 0) r.tmax = 0.05f * length(e);
        rays.push_back(r);
    }
    const BuildOptions build = gpu_test::on_device(GpuKernel::AilaLaineFma);
    const auto fma = build_accel(g, build);
    const auto classic = build_accel(g, gpu_test::on_device(GpuKernel::AilaLaine));
    BuildOptions host_build = build;
    host_build.device = Device{};
    const AilaLaineBvh host = convert_to_aila_laine(build_bvh(g.triangles, host_build), g.triangles);
    std::vector<Hit> got(rays.size()), classic_hits(rays.size());
    std::vector<uint8_t> flags(rays.size(), 2), classic_flags(rays.size(), 2);
    fma->intersect(rays, got);
    fma->occluded(rays, flags);
    classic->intersect(rays, classic_hits);
    classic->occluded(rays, classic_flags);
    size_t mismatches = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit cpu = aila_laine_fma_intersect(host.view(), rays[i]);
        const bool cpu_any = aila_laine_fma_occluded(host.view(), rays[i]);
        const bool same = got[i].found() == cpu.found() && got[i].t == cpu.t && bool(flags[i]) == cpu_any &&
                          classic_hits[i].found() == cpu.found() && classic_hits[i].t == cpu.t &&
                          classic_flags[i] == flags[i];
        if (!same && ++mismatches <= 5)
            ADD_FAILURE() << "ray " << i << ": cpu prim " << cpu.prim << " t " << cpu.t << " any " << cpu_any
                          << ", device prim " << got[i].prim << " t " << got[i].t << " flag " << int(flags[i])
                          << ", aila-laine prim " << classic_hits[i].prim << " t " << classic_hits[i].t;
    }
    EXPECT_EQ(mismatches, 0u);
}

// cwbvh-fma (persistent warps with dynamic fetch, the stack top in shared
// memory) against cwbvh on the same nodes: every ray answered, the same t
// bit for bit (the same triangle test; the primitive may differ only on an
// exact tie), the same any-hit flags; enough rays that warps refill many
// times, and a count that is not a multiple of the warp or block size.
TEST(GpuDeviceTracer, CwbvhFmaAnswersLikeCwbvh) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("spheres");
    const SceneGeometry g = SceneGeometry::build(scene);
    const BruteForceAccel brute(g);
    std::vector<Ray> rays = test_rays(scene, g, brute, 23);
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const Vec3f c = g.bounds.center(), e = g.bounds.extent();
    for (int i = 0; i < 150001; ++i) {
        Ray r;
        r.org = c + Vec3f(u(rng) * e.x, u(rng) * e.y, u(rng) * e.z);
        r.dir = Vec3f(u(rng), u(rng), u(rng));
        if (i % 11 == 0) r.dir[i % 3] = 0.0f;  // axis-parallel components
        if (i % 5 == 0) r.tmax = 0.1f * length(e);
        rays.push_back(r);
    }
    const auto cwbvh = build_accel(g, gpu_test::on_device(GpuKernel::Cwbvh));
    const auto fma = build_accel(g, gpu_test::on_device(GpuKernel::CwbvhFma));
    std::vector<Hit> expected(rays.size()), got(rays.size());
    std::vector<uint8_t> expected_flags(rays.size()), flags(rays.size(), 2);
    cwbvh->intersect(rays, expected);
    fma->intersect(rays, got);
    cwbvh->occluded(rays, expected_flags);
    fma->occluded(rays, flags);
    size_t mismatches = 0, cwbvh_misses = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        bool same = got[i].found() == expected[i].found() && got[i].t == expected[i].t &&
                    flags[i] == expected_flags[i];
        if (!same) {
            // The slab-test cwbvh can miss a closer hit (its relative tmax
            // slack, tests/cwbvh_fma_test.cpp): brute force decides.
            const Hit truth = brute.intersect(rays[i]);
            same = got[i].found() == truth.found() && bool(flags[i]) == truth.found() &&
                   (!truth.found() || std::fabs(got[i].t - truth.t) <= 1e-5f * std::fabs(truth.t));
            cwbvh_misses += same;
        }
        if (!same && ++mismatches <= 5)
            ADD_FAILURE() << "ray " << i << ": cwbvh prim " << expected[i].prim << " t " << expected[i].t
                          << " flag " << int(expected_flags[i]) << ", cwbvh-fma prim " << got[i].prim << " t "
                          << got[i].t << " flag " << int(flags[i]);
    }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_LT(cwbvh_misses, rays.size() / 1000 + 1);
}

TEST(GpuDeviceTracer, EmptySceneAlwaysMisses) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry g;
    std::vector<Ray> rays(100);
    for (Ray& r : rays) r.dir = Vec3f(0.0f, 0.0f, 1.0f);
    for (GpuKernel kernel : all_gpu_kernels()) {
        SCOPED_TRACE(to_string(kernel));
        const auto tracer = build_accel(g, gpu_test::on_device(kernel));
        std::vector<Hit> hits(rays.size());
        tracer->intersect(rays, hits);
        for (const Hit& h : hits) EXPECT_FALSE(h.found());
    }
}

// The hit comparisons with the CPU are bit-exact only when the host code
// takes the FMA branch of trace/triangle_intersect.h as the device does: a
// build for baseline x86-64 (no FMA) would fail them on borderline rays.
TEST(GpuProbe, HostCodeUsesFmaLikeTheDevice) {
    RF_REQUIRE_DEVICE();
#if !defined(__FMA__)
    FAIL() << "host code compiled without FMA: build with -DRAYFORGE_MARCH=x86-64-v3 (scripts/gpu-prebuild.sh) or "
              "-march=native on an FMA CPU";
#endif
}

// The smallest real use of the device; scripts/gpu-run.sh runs it under
// compute-sanitizer to probe whether the runtime lets the sanitizer in.
TEST(GpuProbe, UploadLaunchDownload) {
    RF_REQUIRE_DEVICE();
    std::vector<uint32_t> values(1000);
    for (uint32_t i = 0; i < values.size(); ++i) values[i] = i * 3;
    const std::vector<uint32_t> result = cuda::self_test::add_on_device(values, 7);
    ASSERT_EQ(result.size(), values.size());
    for (uint32_t i = 0; i < values.size(); ++i) EXPECT_EQ(result[i], i * 3 + 7) << i;
}

TEST(GpuErrors, FailingAllocationNamesTheBufferAndSize) {
    RF_REQUIRE_DEVICE();
    try {
        cuda::self_test::allocate_device_buffer(size_t(1) << 50);  // a petabyte
        FAIL() << "no error";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("out of device memory: buffer 'self-test buffer' asked for 1125899906842624 bytes"),
                  std::string::npos)
            << m;
    }
    // The device is still usable afterwards.
    EXPECT_NO_THROW(cuda::self_test::allocate_device_buffer(1 << 20));
}

TEST(GpuErrors, LaunchErrorNamesFileLineAndCudaError) {
    RF_REQUIRE_DEVICE();
    try {
        cuda::self_test::launch_invalid_kernel();
        FAIL() << "no error";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("CUDA error at"), std::string::npos) << m;
        EXPECT_NE(m.find("self_test.cu:"), std::string::npos) << m;
        // The runtime's own words: "invalid configuration argument" up to
        // CUDA 12, "invalid argument" from CUDA 13 (seen on an H200).
        EXPECT_NE(m.find("invalid"), std::string::npos) << m;
        EXPECT_NE(m.find("cudaGetLastError()"), std::string::npos) << m;
    }
    EXPECT_NO_THROW(cuda::self_test::allocate_device_buffer(1 << 20));
}

TEST(GpuErrors, UnknownDeviceIsACleanError) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry g = SceneGeometry::build(make_builtin_scene("cornell"));
    try {
        (void)build_accel(g, gpu_test::on_device(GpuKernel::Cwbvh, {}, 99));
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("cuda:99: no such device"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace rf
