// HLBVH2 builder (Garanzha 2014, dissertation ch. 5): 30-bit Morton codes,
// 15-bit clusters, bottom levels by binary search on Morton bits, top level
// over the cluster boxes by the grid SAH; produces the canonical rf::Bvh.
#pragma once

#include <cstdint>
#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Wall-clock time of each build stage (the dissertation's table 5.1 breakdown).
struct Hlbvh2Stages {
    double morton_ms = 0.0;    // centroid bounds and 30-bit Morton codes
    double sort_ms = 0.0;      // radix sort of (code, triangle), gathering boxes into that order
    double clusters_ms = 0.0;  // compaction into runs of equal 15-bit prefixes
    double bottom_ms = 0.0;    // per-cluster subtrees by binary search, their boxes bottom-up
    double top_ms = 0.0;       // grid-binned SAH tree over the cluster boxes
    double emit_ms = 0.0;      // depth limit and depth-first emission of the canonical BVH
    uint32_t cluster_count = 0;
    [[nodiscard]] double total_ms() const {
        return morton_ms + sort_ms + clusters_ms + bottom_ms + top_ms + emit_ms;
    }
};

Bvh build_hlbvh2(std::span<const Triangle> triangles, const BvhBuildConfig& config);
// The same build, also reporting stage timings into *stages (when not null).
Bvh build_hlbvh2(std::span<const Triangle> triangles, const BvhBuildConfig& config, Hlbvh2Stages* stages);

}  // namespace rf
