// The per-frame updates of rf::DynamicAccel, one method per file in this
// folder, all behind DynamicAccel::update(change):
//   refit     refit_updater.cpp    one build, then the boxes refitted bottom-up (accel/bvh/refit.h)
//   rebuild   rebuild_updater.cpp  BuildOptions::builder from scratch
//   adapt     adapt.cpp            Garanzha 2014 ch. 2: refit, local rebuilds, migrations
//   clusters  cluster_updater.cpp  Garanzha 2014 ch. 3: a build over precomputed clusters' boxes
//   two-level two_level_accel.cpp  a BVH per mesh, a top level over instances
// The first four keep a canonical BVH current through the BvhUpdater seam
// below; dynamic_accel.cpp turns it into the traversal layout (refitting
// that layout in place when only boxes changed, re-collapsing it when the
// topology changed). The two-level method is an accel of its own. On a
// CUDA device backend/cuda/device_dynamic_accel.cpp makes refit, rebuild
// and two-level.
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
