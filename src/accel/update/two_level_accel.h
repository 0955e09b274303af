// The two-level structure's host state (accel/update/two_level_accel.cpp),
// read by its device copy (backend/cuda/device_dynamic_accel.cpp): after
// construction and after each update(), the bottom levels the update
// refitted, the top level rebuilt over the visible instances, and the
// instances as the traversal (trace/two_level_traversal.h) sees them.
#pragma once

#include <cstdint>
#include <memory>
#include <span>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/two_level_traversal.h"

namespace rf {

class TwoLevelHost : public DynamicAccel {
public:
    [[nodiscard]] virtual size_t mesh_count() const = 0;
    // Mesh `mesh`'s canonical BVH (empty when no instance uses the mesh) and
    // the object-space triangles its prim_indices index.
    [[nodiscard]] virtual const Bvh& blas(uint32_t mesh) const = 0;
    [[nodiscard]] virtual std::span<const Triangle> blas_triangles(uint32_t mesh) const = 0;
    // The meshes the last update() refitted (none before the first).
    [[nodiscard]] virtual std::span<const uint32_t> updated_meshes() const = 0;
    [[nodiscard]] virtual const Bvh& top() const = 0;
    [[nodiscard]] virtual std::span<const TwoLevelInstance> instances() const = 0;
};

// Binary bottom levels (BVH2 layout) on the CPU, whatever build.layout and
// build.device say; build.builder builds them.
std::unique_ptr<TwoLevelHost> make_two_level_host(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build);

}  // namespace rf
