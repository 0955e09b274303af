// Treelet restructuring on the device (backend/cuda/treelet_restructure.cu)
// gives the CPU pass's tree bit for bit, on trees of device and host
// builders (clipped SBVH and GridBvhSplit leaves included), for every
// treelet size; build_bvh_on_device with options.treelets equals the CPU
// build and reports the pass's time.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/bvh_build_config.h"
#include "accel/bvh/optimize/treelet_restructure.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/treelet_restructure.h"
#include "gpu_build_checks.h"

namespace rf {
namespace {

using gpu_build_test::expect_same_bvh;

TEST(GpuTreeletRestructuring, EqualsTheCpuPass) {
    RF_REQUIRE_DEVICE();
    std::vector<gpu_build_test::NamedScene> scenes = gpu_build_test::common_scenes();
    gpu_build_test::append_degenerate_scenes(scenes);
    for (const auto& scene : scenes) {
        for (const Builder builder : {Builder::Lbvh30, Builder::Ploc, Builder::BinnedSah, Builder::Sbvh,
                                      Builder::GridBvhSplit}) {
            for (const int leaves : {3, 7}) {
                const std::string what = scene.name + " " + to_string(builder) + " n=" + std::to_string(leaves);
                const BuildOptions options{.builder = builder, .max_leaf_size = builder == Builder::Sbvh ? 2 : 4};
                const BvhBuildConfig config = bvh_build_config(options);
                const TreeletOptions treelets{.enabled = true, .treelet_leaves = leaves};
                const Bvh input = build_bvh(scene.geometry.triangles, options);
                Bvh cpu = input;
                optimize_treelets(cpu, scene.geometry.triangles, config, treelets);
                Bvh device = input;
                cuda::DeviceBuildStages stages;
                cuda::optimize_treelets_on_device(device, scene.geometry.triangles, config, treelets, &stages);
                expect_same_bvh(cpu, device, what);
                if (input.nodes.size() >= 3) EXPECT_GT(stages.treelet_ms, 0.0) << what;
            }
        }
    }
}

// Trees at the depth limit: the device pass hands what its emitter cannot
// lay out within 64 levels to the host's emitter, and still equals the CPU.
TEST(GpuTreeletRestructuring, DeepTreesEqualTheCpuPass) {
    RF_REQUIRE_DEVICE();
    SceneGeometry row;
    float x = 1.0f;
    for (int i = 0; i < 900; ++i, x *= 1.09f) test::append(row, {Vec3f(x, 0, 0), Vec3f(x, 1, 0), Vec3f(x, 0, 1)});
    SceneGeometry chain = test::make_morton_chain(300);
    for (const SceneGeometry* scene : {&row, &chain}) {
        for (const Builder builder : {Builder::Lbvh63, Builder::BinnedSah}) {
            const BuildOptions options{.builder = builder, .max_leaf_size = 1};
            const BvhBuildConfig config = bvh_build_config(options);
            const Bvh input = build_bvh(scene->triangles, options);
            Bvh cpu = input, device = input;
            optimize_treelets(cpu, scene->triangles, config, TreeletOptions{.enabled = true});
            cuda::optimize_treelets_on_device(device, scene->triangles, config, TreeletOptions{.enabled = true});
            expect_same_bvh(cpu, device, "deep " + to_string(builder));
        }
    }
}

TEST(GpuTreeletRestructuring, DeviceBuildsApplyIt) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry scene = test::make_triangle_soup(50000, 3, {Vec3f(-8.0f), Vec3f(8.0f)}, 0.3f);
    for (const Builder builder : {Builder::Lbvh30, Builder::Hlbvh2, Builder::Ploc, Builder::GridBvh}) {
        BuildOptions options;
        options.builder = builder;
        options.treelets.enabled = true;
        cuda::DeviceBuildStages stages;
        const Bvh device = cuda::build_bvh_on_device(scene.triangles, options, &stages);
        expect_same_bvh(build_bvh(scene.triangles, options), device, to_string(builder) + "+treelets");
        EXPECT_GT(stages.treelet_ms, 0.0) << to_string(builder);
        BuildOptions plain = options;
        plain.treelets.enabled = false;
        EXPECT_LT(device.sah_cost(), build_bvh(scene.triangles, plain).sah_cost()) << to_string(builder);
    }
}

}  // namespace
}  // namespace rf
