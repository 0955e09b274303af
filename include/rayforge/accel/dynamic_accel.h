// Acceleration structures kept up to date over an animation: after
// Scene::set_time and SceneGeometry::update, DynamicAccel::update(change)
// makes the structure answer for the new positions, by one of the methods
// of Garanzha 2014 ch. 2-3 or a plain refit/rebuild. Queries go through the
// rf::Accel interface, as for any structure.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/scene/scene.h"

namespace rf {

enum class UpdateMethod : uint8_t {
    Refit,     // boxes recomputed bottom-up, topology kept (CPU and device)
    Adapt,     // Garanzha 2014 ch. 2: refit + local rebuild of exploded subtrees + migration
    Rebuild,   // a full build with BuildOptions::builder every frame (CPU and device)
    Clusters,  // Garanzha 2014 ch. 3: a full build over precomputed clusters' boxes every frame
    TwoLevel,  // (CPU and device) one BVH per mesh (refit only when it deforms) + a top level over instances rebuilt every frame
};

// Whether `method` runs on a CUDA device: refit, rebuild and two-level do;
// adapt and clusters restructure the tree on the host and run on the CPU only.
bool update_runs_on_device(UpdateMethod method);

// Chapter 2's thresholds. The text gives them twice with dM and dE swapped:
// `stated()` is the first reading (dM = 0.05, dE = 0.01), `closing()` the
// closing paragraph's (dM = 0.01, dE = 0.05). MaxOverlap > 0.5 in both.
struct AdaptOptions {
    float migrate_threshold = 0.05f;  // dM: migrating when SAH(N)/Saved(N) < 1 - dM
    float explode_threshold = 0.01f;  // dE: exploded when SAH(N)/Saved(N) > 1 + dE ...
    float max_overlap = 0.5f;         // ... and MaxOverlap(N) above this
    bool migrate = true;              // stage 3 (off: refit + rebuild only)
    bool rebuild = true;              // stage 2 (off: refit + migration only)
    static AdaptOptions stated() { return {}; }
    static AdaptOptions closing() { return {0.01f, 0.05f, 0.5f, true, true}; }
};

// Chapter 3's clusters. Acc(k) = reg - sizeBound * regBound; Naive(k) =
// sum of triangle areas / area of the cluster's box (the baseline).
enum class ClusterHeuristic : uint8_t { Acc, Naive };
// Iterative merging on the dual graph (bucketed priority queue over [-2, 2])
// or iterative growing from random seeds.
enum class ClusterGeneration : uint8_t { Merge, Grow };
struct ClusterOptions {
    ClusterHeuristic heuristic = ClusterHeuristic::Acc;
    ClusterGeneration generation = ClusterGeneration::Merge;
    int max_count = 50;        // MaxCount: about the most distinct vertices a cluster has
    float max_size = 50.0f;    // MaxSize: about the largest cluster, in average-triangle sphere areas
    int leaf_triangles = 32;   // L: the build over clusters stops at nodes of at most this many triangles
    uint64_t seed = 1;         // growing's random start triangles
    // Not in the text: each cluster keeps a BVH over its own triangles (built
    // once, refitted every frame) under its leaf of the tree over cluster
    // boxes, so leaves hold BuildOptions::max_leaf_size triangles, not L.
    bool cluster_subtrees = false;
};

// The method used when neither the caller nor the scene file names one:
// measured as fast as adapt on these scenes, with a full build's quality
// (docs/benchmarks.md).
inline constexpr UpdateMethod kDefaultUpdateMethod = UpdateMethod::Rebuild;

struct UpdateOptions {
    // Unset: the scene file's own method (Scene::render_settings.update),
    // else kDefaultUpdateMethod. A world refuses a method its device cannot
    // run when it is set here, and replaces it, with a note, when it comes
    // from the file.
    std::optional<UpdateMethod> method;
    AdaptOptions adapt;
    ClusterOptions clusters;
};

// One update's work and result.
struct UpdateStats {
    bool updated = false;     // World::set_time and geometry_replaced: the structure was updated (something moved)
    double update_ms = 0.0;   // the tree (or trees) brought up to date
    double layout_ms = 0.0;   // the traversal layout refitted or re-collapsed (included in update_ms)
    double sah_cost = 0.0;    // of the canonical tree after the update (C_trav = C_int = 1)
    // Adapt only (Garanzha 2014, Figs. 2.7-2.10): nodes refitted, subtrees
    // rebuilt (and their nodes), subtrees migrated.
    uint64_t refitted_nodes = 0;
    uint64_t rebuilt_subtrees = 0;
    uint64_t rebuilt_nodes = 0;
    uint64_t migrations = 0;
    // TwoLevel only: bottom-level trees refitted or rebuilt this frame.
    uint64_t meshes_updated = 0;
};

class DynamicAccel : public Accel {
public:
    // Brings the structure up to date with the geometry it was built over,
    // which the caller has updated in place (SceneGeometry::update) as
    // `change` says. Not thread-safe against concurrent queries.
    virtual UpdateStats update(const GeometryChange& change) = 0;
    [[nodiscard]] virtual UpdateMethod method() const = 0;
    // The build when the accel was made (or the last full rebuild).
    [[nodiscard]] virtual double initial_build_ms() const = 0;
    // The structure answering the queries now: this accel on the CPU; on a
    // CUDA device the device structure the method keeps current (rebuild
    // replaces it every frame). A renderer on a device binds to it, so make
    // a new renderer after each update there.
    [[nodiscard]] virtual const Accel& current() const { return *this; }
};

// A dynamic structure over `geometry` (the flat triangles of `scene`; both
// must outlive it): `build` names the builder for the initial build, for
// rebuilds (Rebuild, Adapt's local rebuilds, Clusters' builds over boxes,
// TwoLevel's trees), the layout traced on the CPU and the device. Throws
// rf::Error for invalid options or a method the device does not support.
std::unique_ptr<DynamicAccel> build_dynamic_accel(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build, const UpdateOptions& update,
                                                  const ProgressCallback& progress = {});

// Names: refit, adapt, rebuild, clusters, two-level; acc, naive; merge, grow;
// adapt readings: stated, closing. parse_* throw rf::Error when unknown.
UpdateMethod parse_update_method(const std::string& name);
ClusterHeuristic parse_cluster_heuristic(const std::string& name);
ClusterGeneration parse_cluster_generation(const std::string& name);
AdaptOptions parse_adapt_reading(const std::string& name);
// Throws rf::Error naming the first option out of its range (build_dynamic_accel calls it).
void validate_update_options(const UpdateOptions& update);
std::string to_string(UpdateMethod method);
std::string to_string(ClusterHeuristic heuristic);
std::string to_string(ClusterGeneration generation);

}  // namespace rf
