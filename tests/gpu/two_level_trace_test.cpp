// The two-level traversal on the device (backend/cuda/two_level_trace.cu)
// answers like the same RF_HD code on the CPU (trace/two_level_traversal.h)
// over the same arrays: rigidly placed, rotated, non-uniformly scaled
// instances of two closed meshes, one hidden. Skips without a device.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "accel/bvh/builders/build_bvh.h"
#include "backend/cuda/two_level_trace.h"
#include "gpu_test_device.h"
#include "rayforge/io/scene_io.h"

namespace rf {
namespace {

TEST(GpuTwoLevel, ClosestAndAnyHitMatchCpu) {
    RF_REQUIRE_DEVICE();
    // Two meshes of a builtin scene, instanced 64 times.
    Scene scene = make_builtin_scene("spheres");
    std::mt19937 rng(4);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Instance> instances;
    for (int i = 0; i < 64; ++i) {
        const Vec3f axis = normalize(Vec3f(unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) + 0.1f));
        instances.push_back({uint32_t(i % 2) % uint32_t(scene.meshes.size()),
                             Affine3f::translation(Vec3f(unit(rng), unit(rng), unit(rng)) * 40.0f) *
                                 Affine3f::rotation(axis, 6.0f * unit(rng)) *
                                 Affine3f::scale(Vec3f(0.5f + unit(rng), 0.5f + unit(rng), 0.5f + unit(rng)))});
    }
    scene.instances = instances;
    const SceneGeometry g = SceneGeometry::build(scene);

    std::vector<std::vector<Triangle>> object(scene.meshes.size());
    std::vector<Bvh> blas(scene.meshes.size());
    std::vector<BvhView> views(scene.meshes.size());
    for (size_t m = 0; m < scene.meshes.size(); ++m) {
        const Mesh& mesh = scene.meshes[m];
        for (size_t t = 0; t < mesh.triangle_count(); ++t)
            object[m].push_back({mesh.positions[mesh.indices[3 * t]], mesh.positions[mesh.indices[3 * t + 1]],
                                 mesh.positions[mesh.indices[3 * t + 2]]});
        blas[m] = build_bvh_on_cpu(object[m], BuildOptions{});
        views[m] = BvhView{blas[m].nodes.data(), blas[m].prim_indices.data(), object[m].data(),
                           uint32_t(blas[m].nodes.size())};
    }
    std::vector<TwoLevelInstance> visible;
    std::vector<Triangle> boxes;
    for (uint32_t i = 0; i < scene.instances.size(); ++i) {
        if (i == 5) continue;  // hidden
        const Instance& inst = scene.instances[i];
        if (blas[inst.mesh].nodes.empty()) continue;
        visible.push_back({inst.transform.inverse(), inst.mesh, g.instance_first_triangle[i]});
        Box3f box = inst.transform.transform_box(blas[inst.mesh].nodes[0].bounds);
        box = Box3f{box.lo - Vec3f(1e-3f), box.hi + Vec3f(1e-3f)};
        boxes.push_back({box.lo, box.hi, box.center()});
    }
    BuildOptions top_options;
    top_options.max_leaf_size = 2;
    const Bvh top = build_bvh_on_cpu(boxes, top_options);
    const TwoLevelBvh2Tracer cpu{TwoLevelView<BvhView>{top.nodes.data(), top.prim_indices.data(),
                                                       uint32_t(top.nodes.size()), visible.data(), views.data()}};
    const cuda::DeviceTwoLevel device(0, blas, object, top, visible);

    std::vector<Ray> rays(100000);
    for (Ray& r : rays) {
        r.org = g.bounds.lo + Vec3f(unit(rng), unit(rng), unit(rng)) * g.bounds.extent();
        r.dir = normalize(Vec3f(unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) - 0.5f) + Vec3f(1e-3f, 0, 0));
    }
    std::vector<Hit> hits(rays.size());
    std::vector<uint8_t> occluded(rays.size());
    device.intersect(rays, hits);
    device.occluded(rays, occluded);
    size_t mismatches = 0, found = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
        const Hit want = cpu.intersect(rays[i]);
        found += want.found() ? 1 : 0;
        const bool same = want.prim == hits[i].prim &&
                          (!want.found() || std::fabs(want.t - hits[i].t) <= 1e-5f * std::fabs(want.t));
        if (!same || (cpu.occluded(rays[i]) ? 1 : 0) != occluded[i]) ++mismatches;
    }
    EXPECT_GT(found, rays.size() / 10);
    EXPECT_LE(mismatches, rays.size() / 10000) << "contracted arithmetic may differ on edges, nowhere else";
}

}  // namespace
}  // namespace rf
