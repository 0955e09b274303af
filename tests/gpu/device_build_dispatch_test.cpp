// --device cuda builds (issue 7 item 7): build_bvh_on_device dispatches every
// builder with a device version and equals rf::build_bvh; DeviceTracer built
// on the device traces exactly what the host-built tracer traces, and says
// where it was built.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "../accel_test_rays.h"
#include "accel/bvh/builders/build_bvh.h"
#include "gpu_build_checks.h"
#include "rayforge/backend/cuda.h"
#include "rayforge/backend/cuda_build.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gpu_build_test::expect_same_bvh;

constexpr Builder kDeviceBuilders[] = {Builder::Lbvh30, Builder::Lbvh63,  Builder::Hlbvh2,
                                       Builder::Ploc,   Builder::GridBvh, Builder::GridBvhSplit};

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
        BuildOptions on_device, on_host;
        on_device.builder = on_host.builder = c.builder;
        on_host.build_on_device = false;
        const cuda::DeviceTracer device(scene, c.kernel, on_device);
        const cuda::DeviceTracer host(scene, c.kernel, on_host);
        const std::string what = to_string(c.kernel) + "/" + to_string(c.builder);
        // Where it was built: binned has no device builder, but its layout
        // conversion (and a grid's build) runs on the device.
        const bool device_structure = cuda::has_device_builder(c.builder) || c.kernel == GpuKernel::ProximityGrid;
        EXPECT_EQ(device.build_stages().on_device, device_structure) << what;
        EXPECT_FALSE(host.build_stages().on_device) << what;
        if (c.kernel == GpuKernel::AilaLaine || c.kernel == GpuKernel::Cwbvh)
            EXPECT_GT(device.build_stages().layout_ms, 0.0) << what;
        EXPECT_EQ(device.stats().node_count, host.stats().node_count) << what;
        std::vector<Hit> a(rays.size()), b(rays.size());
        device.intersect(rays, a);
        host.intersect(rays, b);
        size_t differ = 0;
        for (size_t i = 0; i < rays.size(); ++i) differ += a[i].prim != b[i].prim || a[i].t != b[i].t;
        EXPECT_EQ(differ, 0u) << what;  // the same structure, bit for bit, traced by the same kernel
    }
}

}  // namespace
}  // namespace rf
