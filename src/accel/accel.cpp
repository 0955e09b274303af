// build_accel: option checking and dispatch; the batched queries every Accel
// inherits.
#include "rayforge/accel/accel.h"
#include "core/parallel.h"

#include <cmath>

#include "accel/brute_force.h"
#include "accel/bvh/bvh_accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

void validate(const BuildOptions& options) {
    if (options.bin_count < 2 || options.bin_count > 256) {
        throw Error("build options: bin_count must be in [2, 256], got " + std::to_string(options.bin_count));
    }
    if (options.max_leaf_size < 1 || options.max_leaf_size > 64) {
        throw Error("build options: max_leaf_size must be in [1, 64], got " +
                    std::to_string(options.max_leaf_size));
    }
    if (!(options.traversal_cost > 0.0f) || !std::isfinite(options.traversal_cost)) {
        throw Error("build options: traversal_cost must be a positive number, got " +
                    std::to_string(options.traversal_cost));
    }
    if (!(options.intersection_cost > 0.0f) || !std::isfinite(options.intersection_cost)) {
        throw Error("build options: intersection_cost must be a positive number, got " +
                    std::to_string(options.intersection_cost));
    }
    if (options.threads < 0) {
        throw Error("build options: threads must be >= 0 (0 = all cores), got " + std::to_string(options.threads));
    }
}

constexpr size_t kRayGrainSize = 256;
constexpr size_t kMaxTriangles = 0x7FFFFFFF;

}  // namespace

std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options) {
    validate(options);
    // Node indices are 32-bit and a BVH over n triangles may need 2n - 1 nodes.
    if (geometry.triangles.size() > kMaxTriangles) {
        throw Error("build_accel: " + std::to_string(geometry.triangles.size()) +
                    " triangles exceed the limit of " + std::to_string(kMaxTriangles));
    }
    switch (options.structure) {
        case Structure::Bvh: return std::make_unique<BvhAccel>(geometry, options);
        case Structure::BruteForce: return std::make_unique<BruteForceAccel>(geometry);
    }
    throw Error("build options: unknown structure");
}

Structure parse_structure(const std::string& name) {
    if (name == "bvh") return Structure::Bvh;
    if (name == "brute") return Structure::BruteForce;
    throw Error("unknown acceleration structure '" + name + "' (expected bvh or brute)");
}

Builder parse_builder(const std::string& name) {
    if (name == "binned") return Builder::BinnedSah;
    throw Error("unknown BVH builder '" + name + "' (expected binned)");
}

void Accel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (rays.size() != hits.size()) {
        throw Error("Accel::intersect: " + std::to_string(rays.size()) + " rays but " +
                    std::to_string(hits.size()) + " hit slots");
    }
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) hits[i] = intersect(rays[i]);
    });
}

bool Accel::count_traversal(std::span<const Ray>, bool, TraversalTotals&) const { return false; }

void Accel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    if (rays.size() != occluded.size()) {
        throw Error("Accel::occluded: " + std::to_string(rays.size()) + " rays but " +
                    std::to_string(occluded.size()) + " result slots");
    }
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) occluded[i] = this->occluded(rays[i]) ? 1 : 0;
    });
}

}  // namespace rf
