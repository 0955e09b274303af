// The seam between build_dynamic_accel (dynamic_accel.cpp) and the update
// methods over flat triangles: each keeps a canonical BVH current for the
// triangles' new positions; the dynamic accel turns it into the traversal
// layout (refitting that layout in place when only boxes changed,
// re-collapsing it when the topology changed). One method per file:
//   refit     accel/bvh/refit.cpp           (parallel bottom-up)
//   rebuild   accel/dynamic/dynamic_accel.cpp (build_bvh_on_cpu every frame)
//   adapt     accel/bvh/update/adapt.cpp    (Garanzha 2014 ch. 2)
//   clusters  accel/bvh/builders/clusters.cpp (Garanzha 2014 ch. 3)
// The two-level method is an accel of its own (accel/dynamic/two_level_accel.cpp).
#pragma once

#include <memory>
#include <span>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

class BvhUpdater {
public:
    virtual ~BvhUpdater() = default;
    // The canonical BVH over the current triangles (prim_indices index them).
    [[nodiscard]] virtual const Bvh& bvh() const = 0;
    // Brings bvh() up to date with `triangles` (same count and order as at
    // construction, new positions) and fills the method's fields of `stats`
    // (not the times). Returns true when the topology changed (the layout
    // must be re-collapsed), false when only boxes changed.
    virtual bool update(std::span<const Triangle> triangles, UpdateStats& stats) = 0;
};

// Each method's updater, built over the current triangles with build.builder
// (and the other build options; the build runs on build.threads threads).
std::unique_ptr<BvhUpdater> make_refit_updater(std::span<const Triangle> triangles, const BuildOptions& build);
std::unique_ptr<BvhUpdater> make_rebuild_updater(std::span<const Triangle> triangles, const BuildOptions& build);
std::unique_ptr<BvhUpdater> make_adapt_updater(std::span<const Triangle> triangles, const BuildOptions& build,
                                               const AdaptOptions& options);
// Clusters need the meshes' connectivity (shared vertex indices).
std::unique_ptr<BvhUpdater> make_cluster_updater(const Scene& scene, const SceneGeometry& geometry,
                                                 const BuildOptions& build, const ClusterOptions& options);

// The two-level structure: one BVH per mesh, a top level over instances.
std::unique_ptr<DynamicAccel> make_two_level_accel(const Scene& scene, const SceneGeometry& geometry,
                                                   const BuildOptions& build);

}  // namespace rf
