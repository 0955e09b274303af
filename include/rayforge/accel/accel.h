// The one interface every acceleration structure answers ray queries through.
// Integrators and the bench only see Accel; they never know which structure
// (or builder, or layout) is behind it.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

enum class Structure : uint8_t { Bvh, BruteForce };
enum class Builder : uint8_t { BinnedSah };

struct BuildOptions {
    Structure structure = Structure::Bvh;
    Builder builder = Builder::BinnedSah;
    int bin_count = 16;          // SAH bins per axis (binned builders)
    int max_leaf_size = 4;       // leaves never hold more primitives than this
    float traversal_cost = 1.0f; // SAH C_trav
    float intersection_cost = 1.0f;  // SAH C_int
    int threads = 0;             // 0 = all cores
};

struct AccelStats {
    std::string name;            // e.g. "bvh/binned"
    double build_ms = 0.0;       // triangles in memory -> traversable, layout conversion included
    double layout_ms = 0.0;      // the layout conversion alone (0 when traced in the built form)
    size_t node_count = 0;
    size_t leaf_count = 0;
    size_t bytes = 0;            // structure memory, excluding the triangles
    // Tree quality; NaN where the metric does not apply (e.g. brute force).
    double sah_cost = 0.0;       // C_trav = C_int = 1, normalised by root area
    double quality_cost = 0.0;   // Garanzha's formula 4.2, C(root) with nc = 2 (quality = 1 / C)
};

// Work done by traversals, summed over rays (the instrumented pass of the bench).
struct TraversalTotals {
    uint64_t rays = 0;
    uint64_t steps = 0;        // node visits (box tests) in trees, cells visited in grids
    uint64_t prim_tests = 0;   // ray-triangle tests
    uint64_t restarts = 0;     // kd-tree restarts (0 elsewhere)
};

class Accel {
public:
    virtual ~Accel() = default;
    // Closest hit with t in [ray.tmin, ray.tmax]; Hit::found() is false on a miss.
    [[nodiscard]] virtual Hit intersect(const Ray& ray) const = 0;
    // Any hit with t in [ray.tmin, ray.tmax].
    [[nodiscard]] virtual bool occluded(const Ray& ray) const = 0;
    // Batches (parallel over rays); hits.size() == rays.size().
    virtual void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    virtual void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    [[nodiscard]] virtual AccelStats stats() const = 0;
    // Instrumented traversal of every ray (closest hit, or any hit), adding
    // its work to `totals`; false when the structure keeps no counters.
    virtual bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const;
};

// Builds the structure named in `options` over `geometry`, which must outlive
// the result. Throws rf::Error for invalid options.
std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options = {});

// Names for the CLI and scene files ("bvh", "brute"; "binned"); throw rf::Error when unknown.
Structure parse_structure(const std::string& name);
Builder parse_builder(const std::string& name);

}  // namespace rf
