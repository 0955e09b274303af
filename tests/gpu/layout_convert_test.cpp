// The device layout conversions (backend/cuda/layout_convert.cu) against the
// CPU ones: Aila-Laine node pairs equal convert_to_aila_laine's and the CWBVH
// equals build_cwbvh's (nodes and triangles bit for bit, root, counts,
// depth) on BVHs from several builders and scenes, a one-leaf BVH, a single
// triangle and the empty BVH; the kernels' time is reported; malformed BVHs
// throw. The device-resident chain (the tree kept on the device from the
// builder to the layout, issue 33 item 3) gives the host chain's arrays bit
// for bit for every Morton-family device builder, and DeviceTracer over it
// the host chain's hits. Skips with a message when no CUDA device is present.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "../accel_test_scenes.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "gpu_build_checks.h"
#include "rayforge/accel/accel.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_tracer.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gpu_build_test::NamedScene;

struct NamedBvh {
    std::string name;
    std::vector<Triangle> triangles;
    Bvh bvh;
};

std::vector<NamedBvh> test_bvhs() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(5))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    scenes.push_back({"far", test::make_triangle_soup(3000, 3, {Vec3f(1e6f), Vec3f(1e6f + 100.0f)}, 1.0f)});
    gpu_build_test::append_degenerate_scenes(scenes);
    std::vector<NamedBvh> out;
    const Builder builders[] = {Builder::BinnedSah, Builder::Sbvh, Builder::Lbvh30, Builder::Ploc};
    for (size_t i = 0; i < scenes.size(); ++i) {
        BuildOptions options;
        options.builder = builders[i % 4];
        options.max_leaf_size = i % 2 == 0 ? 4 : 8;
        out.push_back({scenes[i].name + " " + to_string(options.builder), scenes[i].geometry.triangles,
                       build_bvh(scenes[i].geometry.triangles, options)});
    }
    std::vector<Triangle> few = {{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)},
                                 {Vec3f(0, 0, 1), Vec3f(1, 0, 1), Vec3f(0, 1, 2)},
                                 {Vec3f(2, 0, 0), Vec3f(3, 0, 0), Vec3f(2, 1, 0)}};
    BuildOptions one_leaf;
    one_leaf.max_leaf_size = 8;
    out.push_back({"one leaf", few, build_bvh(few, one_leaf)});
    few.resize(1);
    out.push_back({"one triangle", few, build_bvh(few, one_leaf)});
    out.push_back({"empty", {}, Bvh{}});
    return out;
}

template <class T>
size_t differing(const std::vector<T>& a, const std::vector<T>& b) {
    if (a.size() != b.size()) return a.size() + b.size();
    size_t wrong = 0;
    for (size_t i = 0; i < a.size(); ++i) wrong += std::memcmp(&a[i], &b[i], sizeof(T)) != 0;
    return wrong;
}

TEST(GpuLayoutConvert, AilaLaineEqualsCpuConversion) {
    RF_REQUIRE_DEVICE();
    for (const NamedBvh& c : test_bvhs()) {
        const AilaLaineBvh expected = convert_to_aila_laine(c.bvh, c.triangles);
        double ms = -1.0;
        const AilaLaineBvh got = cuda::convert_to_aila_laine_on_device(c.bvh, c.triangles, &ms);
        EXPECT_EQ(differing(expected.nodes, got.nodes), 0u) << c.name << ": node pairs that differ";
        EXPECT_EQ(differing(expected.triangles, got.triangles), 0u) << c.name << ": leaf float4s that differ";
        EXPECT_EQ(expected.root, got.root) << c.name;
        EXPECT_TRUE(gpu_build_test::same_box(expected.bounds, got.bounds)) << c.name;
        EXPECT_EQ(expected.leaf_count, got.leaf_count) << c.name;
        EXPECT_EQ(expected.triangle_refs, got.triangle_refs) << c.name;
        if (c.bvh.nodes.empty()) {
            EXPECT_EQ(ms, 0.0) << c.name;
        } else {
            EXPECT_GT(ms, 0.0) << c.name;
        }
    }
}

TEST(GpuLayoutConvert, CwbvhEqualsCpuBuild) {
    RF_REQUIRE_DEVICE();
    for (const NamedBvh& c : test_bvhs()) {
        const CwbvhBvh expected = build_cwbvh(c.bvh, c.triangles);
        double ms = -1.0;
        const CwbvhBvh got = cuda::build_cwbvh_on_device(c.bvh, c.triangles, &ms);
        EXPECT_EQ(differing(expected.nodes, got.nodes), 0u) << c.name << ": wide nodes that differ";
        EXPECT_EQ(differing(expected.triangles, got.triangles), 0u) << c.name << ": triangles that differ";
        EXPECT_EQ(expected.leaf_count, got.leaf_count) << c.name;
        EXPECT_EQ(expected.depth, got.depth) << c.name;
        if (c.bvh.nodes.empty()) {
            EXPECT_EQ(ms, 0.0) << c.name;
        } else {
            EXPECT_GT(ms, 0.0) << c.name;
        }
    }
}

TEST(GpuLayoutConvert, MalformedBvhThrows) {
    RF_REQUIRE_DEVICE();
    const std::vector<Triangle> tris = {{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)}};
    Bvh bad;
    bad.nodes.resize(3);
    bad.nodes[0].first = 1;  // inner, children 1 and 2
    bad.nodes[1].count = 1;
    bad.nodes[2].count = 1;
    bad.nodes[2].first = 1;
    bad.prim_indices = {0, 5};  // 5: out of range
    EXPECT_THROW((void)cuda::convert_to_aila_laine_on_device(bad, tris), Error);
    EXPECT_THROW((void)cuda::build_cwbvh_on_device(bad, tris), Error);
    bad.prim_indices = {0, 0};
    bad.nodes[0].first = 2;  // children 2 and 3: out of range
    EXPECT_THROW((void)cuda::convert_to_aila_laine_on_device(bad, tris), Error);
    EXPECT_THROW((void)cuda::build_cwbvh_on_device(bad, tris), Error);
}

// Scenes for the resident chain: every device builder on them, tiny ones
// too (one and three triangles, where the host emits; none).
std::vector<NamedScene> resident_scenes() {
    std::vector<NamedScene> scenes;
    scenes.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    scenes.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    scenes.push_back({"nasty", test::make_nasty_geometry(2)});
    gpu_build_test::append_degenerate_scenes(scenes);
    SceneGeometry few;
    few.triangles = {{Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)},
                     {Vec3f(0, 0, 1), Vec3f(1, 0, 1), Vec3f(0, 1, 2)},
                     {Vec3f(2, 0, 0), Vec3f(3, 0, 0), Vec3f(2, 1, 0)}};
    scenes.push_back({"three triangles", few});
    few.triangles.resize(1);
    scenes.push_back({"one triangle", few});
    scenes.push_back({"empty", SceneGeometry{}});
    return scenes;
}

const Builder kResidentBuilders[] = {Builder::Lbvh30, Builder::Lbvh63, Builder::Hlbvh2, Builder::Ploc,
                                     Builder::Hploc,  Builder::GridBvh};

BuildOptions resident_options(Builder builder, int max_leaf_size) {
    BuildOptions options;
    options.builder = builder;
    options.max_leaf_size = max_leaf_size;
    options.build_on_device = true;
    return options;
}

// The host chain: the device build downloaded, converted from the host Bvh.
TEST(GpuLayoutConvert, ResidentChainEqualsHostChain) {
    RF_REQUIRE_DEVICE();
    for (const NamedScene& scene : resident_scenes()) {
        const std::vector<Triangle>& tris = scene.geometry.triangles;
        for (const Builder builder : kResidentBuilders) {
            for (const int leaf : {1, 4}) {
                const BuildOptions options = resident_options(builder, leaf);
                const std::string what = scene.name + " " + to_string(builder) + " leaf " + std::to_string(leaf);
                const Bvh host = cuda::build_bvh_on_device(tris, options);

                const AilaLaineBvh al_expected = cuda::convert_to_aila_laine_on_device(host, tris);
                const AilaLaineBvh al = cuda::resident_aila_laine_on_device(tris, options);
                EXPECT_EQ(differing(al_expected.nodes, al.nodes), 0u) << what << ": node pairs that differ";
                EXPECT_EQ(differing(al_expected.triangles, al.triangles), 0u) << what << ": leaf float4s";
                EXPECT_EQ(al_expected.root, al.root) << what;
                EXPECT_EQ(al_expected.leaf_count, al.leaf_count) << what;
                EXPECT_EQ(al_expected.triangle_refs, al.triangle_refs) << what;
                if (!host.nodes.empty()) {
                    EXPECT_TRUE(gpu_build_test::same_box(al_expected.bounds, al.bounds)) << what;
                }

                const CwbvhBvh cw_expected = cuda::build_cwbvh_on_device(host, tris);
                const CwbvhBvh cw = cuda::resident_cwbvh_on_device(tris, options);
                EXPECT_EQ(differing(cw_expected.nodes, cw.nodes), 0u) << what << ": wide nodes that differ";
                EXPECT_EQ(differing(cw_expected.triangles, cw.triangles), 0u) << what << ": CWBVH triangles";
                EXPECT_EQ(cw_expected.leaf_count, cw.leaf_count) << what;
                EXPECT_EQ(cw_expected.depth, cw.depth) << what;
            }
        }
    }
}

// DeviceTracer: a device build not refittable runs the resident chain, a
// refittable one the host chain; the same hits bit for bit, every layout,
// and a time to first ray is reported.
TEST(GpuLayoutConvert, ResidentTracerHitsEqualHostChain) {
    RF_REQUIRE_DEVICE();
    const SceneGeometry soup = gpu_build_test::hit_test_soup();
    std::mt19937 rng(41);
    std::uniform_real_distribution<float> u(-12.0f, 12.0f);
    std::vector<Ray> rays(3000);
    for (Ray& ray : rays) {
        ray.org = Vec3f(u(rng), u(rng), u(rng));
        ray.dir = normalize(Vec3f(u(rng), u(rng), u(rng)) - ray.org + Vec3f(1e-3f, 0.0f, 0.0f));
    }
    const GpuKernel kernels[] = {GpuKernel::Bvh2, GpuKernel::AilaLaine, GpuKernel::Cwbvh, GpuKernel::CwbvhFma};
    for (const Builder builder : kResidentBuilders) {
        for (const GpuKernel kernel : kernels) {
            BuildOptions options = resident_options(builder, 4);
            options.gpu_kernel = kernel;
            options.device = {Device::Kind::Cuda, 0};
            const std::string what = to_string(builder) + " " + to_string(kernel);
            const cuda::DeviceTracer resident(soup, options, cuda::Refittable::No);
            const cuda::DeviceTracer host_chain(soup, options, cuda::Refittable::Yes);
            std::vector<Hit> got(rays.size()), expected(rays.size());
            resident.intersect(rays, got);
            host_chain.intersect(rays, expected);
            EXPECT_EQ(differing(expected, got), 0u) << what << ": hits that differ";
            EXPECT_GT(resident.build_stages().first_ray_ms, 0.0) << what;
            EXPECT_GT(resident.build_stages().build_span_ms, 0.0) << what;
            EXPECT_EQ(resident.stats().node_count, host_chain.stats().node_count) << what;
            EXPECT_EQ(resident.stats().sah_cost, host_chain.stats().sah_cost) << what;
        }
    }
}

}  // namespace
}  // namespace rf
