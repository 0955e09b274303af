// The two-level structure (accel/update/two_level_accel.cpp) on a CUDA
// device: binary bottom levels in object space, the binary top level over
// instance world boxes and the instances' inverse transforms, copied there
// as they are; traced one thread per ray by trace/two_level_traversal.h's
// TwoLevelBvh2Tracer, the code the CPU tests run.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/two_level_traversal.h"

namespace rf::cuda {

class DeviceTwoLevel {
public:
    // An empty structure (every ray misses) for `mesh_count` meshes on `device`.
    DeviceTwoLevel(int device, size_t mesh_count);
    // Per mesh its BVH over its object-space triangles (empty for unused
    // meshes); `top` names indices into `instances` (the visible ones).
    DeviceTwoLevel(int device, std::span<const Bvh> blas, std::span<const std::vector<Triangle>> triangles,
                   const Bvh& top, std::span<const TwoLevelInstance> instances);
    ~DeviceTwoLevel();
    DeviceTwoLevel(const DeviceTwoLevel&) = delete;
    DeviceTwoLevel& operator=(const DeviceTwoLevel&) = delete;

    // Mesh `mesh`'s bottom level, copied (after a build or a refit).
    void set_mesh(uint32_t mesh, const Bvh& blas, std::span<const Triangle> triangles);
    // The top level and its instances, copied (every frame).
    void set_top(const Bvh& top, std::span<const TwoLevelInstance> instances);

    // What a kernel takes by value; valid until the next set_*.
    [[nodiscard]] const TwoLevelBvh2Tracer& tracer() const;
    [[nodiscard]] int device() const;
    // Device memory of both levels.
    [[nodiscard]] size_t bytes() const;

    // Host rays in, host answers out (upload, one launch, download).
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rf::cuda
