// Device builds: build_bvh_on_device dispatches every builder with a device
// version and equals the CPU build, as does the public rf::build_bvh on a
// CUDA device; an accel built on the device traces exactly what the
// host-built one traces, and its BuildReport says where it was built.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "../accel_test_rays.h"
#include "accel/bvh/builders/build_bvh.h"
#include "gpu_build_checks.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gpu_build_test::expect_same_bvh;

constexpr Builder kDeviceBuilders[] = {Builder::Lbvh30,  Builder::Lbvh63, Builder::Hlbvh2,      Builder::Ploc,
                                       Builder::Hploc,   Builder::GridBvh, Builder::GridBvhSplit};

TEST(GpuDeviceBuild, WhichBuildersHaveADeviceVersion) {
    for (const Builder b : kDeviceBuilders) EXPECT_TRUE(cuda::has_device_builder(b)) << to_string(b);
    for (const Builder b : {Builder::BinnedSah, Builder::SweepSah, Builder::Sbvh})
        EXPECT_FALSE(cuda::has_device_builder(b)) << to_string(b);
}

TEST(GpuDeviceBuild, EveryDeviceBuilderEqualsItsCpuBuilder) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry scene = test::make_triangle_soup(20000, 7, {Vec3f(-4.0f), Vec3f(4.0f)}, 0.3f);
    for (const Builder builder : kDeviceBuilders) {
        for (const bool optimize : {false, true}) {
            BuildOptions options;
            options.builder = builder;
            options.reinsertion.enabled = optimize;
            cuda::DeviceBuildStages stages;
            const Bvh device = cuda::build_bvh_on_device(scene.triangles, options, &stages);
            const std::string what = to_string(builder) + (optimize ? "+opt" : "");
            expect_same_bvh(build_bvh(scene.triangles, options), device, what);
            // The public entry point with a CUDA device gives the same tree and reports its stages.
            BuildOptions public_options = options;
            public_options.device = parse_device("cuda:0");
            BuildReport report;
            expect_same_bvh(device, build_bvh(scene.triangles, public_options, &report), what + " (rf::build_bvh)");
            EXPECT_TRUE(report.on_device) << what;
            EXPECT_FALSE(report.device_stages.empty()) << what;
            EXPECT_TRUE(stages.on_device) << what;
            EXPECT_GT(stages.device_total_ms(), 0.0) << what;
            EXPECT_GT(stages.peak_device_bytes, 0u) << what;
            EXPECT_EQ(stages.optimize_ms > 0.0, optimize) << what;
        }
    }
    BuildOptions binned;
    EXPECT_THROW((void)cuda::build_bvh_on_device(scene.triangles, binned), Error);
}

TEST(GpuDeviceBuild, TracerBuiltOnTheDeviceTracesLikeTheHostBuiltOne) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry scene = test::to_geometry(test::make_icosphere(4));
    const std::vector<Ray> rays = test::make_rays(scene, 4000, 3);
    struct Case {
        GpuKernel kernel;
        Builder builder;
    };
    for (const Case c : {Case{GpuKernel::Cwbvh, Builder::Hlbvh2}, Case{GpuKernel::AilaLaine, Builder::Ploc},
                         Case{GpuKernel::Bvh2, Builder::GridBvhSplit}, Case{GpuKernel::Cwbvh, Builder::BinnedSah},
                         Case{GpuKernel::ProximityGrid, Builder::BinnedSah}}) {
        BuildOptions options;
        options.builder = c.builder;
        const BuildOptions on_device = gpu_test::on_device(c.kernel, options);
        BuildOptions on_host = on_device;
        on_host.build_on_device = false;
        const auto device = build_accel(scene, on_device);
        const auto host = build_accel(scene, on_host);
        const std::string what = to_string(c.kernel) + "/" + to_string(c.builder);
        // Where it was built: binned has no device builder, but its layout
        // conversion (and a grid's build) runs on the device.
        const bool device_structure = cuda::has_device_builder(c.builder) || c.kernel == GpuKernel::ProximityGrid;
        EXPECT_EQ(device->build_report().on_device, device_structure) << what;
        EXPECT_FALSE(host->build_report().on_device) << what;
        if (c.kernel == GpuKernel::AilaLaine || c.kernel == GpuKernel::Cwbvh)
            EXPECT_GT(device->build_report().layout_ms, 0.0) << what;
        EXPECT_EQ(device->stats().node_count, host->stats().node_count) << what;
        std::vector<Hit> a(rays.size()), b(rays.size());
        device->intersect(rays, a);
        host->intersect(rays, b);
        size_t differ = 0;
        for (size_t i = 0; i < rays.size(); ++i) differ += a[i].prim != b[i].prim || a[i].t != b[i].t;
        EXPECT_EQ(differ, 0u) << what;  // the same structure, bit for bit, traced by the same kernel
    }
}

// The device stages as the public BuildReport (no device needed): the stages
// that ran, in pipeline order, their sum, the host's part and the sizes.
TEST(GpuDeviceBuild, ReportListsTheStagesThatRan) {
    cuda::DeviceBuildStages s;
    s.on_device = true;
    s.bounds_ms = 0.5;
    s.sort_ms = 1.5;
    s.clusters_ms = 0.25;
    s.bottom_ms = 2.0;
    s.boxes_ms = 0.75;
    s.emit_ms = 3.0;
    s.optimize_ms = 4.0;
    s.peak_device_bytes = 3u << 20;
    s.cluster_count = 7;
    s.bottom_levels = 9;
    const BuildReport b = cuda::describe_device_build(s, parse_device("cuda:1"));
    EXPECT_EQ(b.device, parse_device("cuda:1"));
    ASSERT_EQ(b.device_stages.size(), 5u);
    const char* order[] = {"bounds", "sort", "clusters", "bottom", "boxes"};
    for (size_t i = 0; i < 5; ++i) EXPECT_EQ(b.device_stages[i].first, order[i]);
    EXPECT_DOUBLE_EQ(b.device_ms, 5.0);
    EXPECT_DOUBLE_EQ(b.host_ms, 7.0);
    EXPECT_EQ(b.peak_device_bytes, 3u << 20);
    EXPECT_EQ(b.detail, "7 clusters, 9 bottom levels");
    // A device emission is the last device stage and counts in the device total.
    s.device_emit_ms = 0.5;
    const BuildReport emitted = cuda::describe_device_build(s, parse_device("cuda"));
    ASSERT_EQ(emitted.device_stages.size(), 6u);
    EXPECT_EQ(emitted.device_stages.back().first, "emission");
    EXPECT_DOUBLE_EQ(emitted.device_ms, 5.5);
    s.on_device = false;
    EXPECT_FALSE(cuda::describe_device_build(s, parse_device("cuda")).on_device);
}

}  // namespace
}  // namespace rf
