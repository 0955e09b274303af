// The canonical BVH of an HLBVH2 raw tree built elsewhere (the CUDA HLBVH2,
// backend/cuda/hlbvh2_build.cu: bottom trees in one launch, the top level
// by task queues in hlbvh2_top_level.cu): the host half of the device build.
// A forest without a top level gets the CPU builder's own (hlbvh2.cpp, the
// grid SAH of hlbvh2_top_steps.h), so the result is build_hlbvh2's.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// The bottom levels as the device leaves them (hlbvh2_bottom_steps.h build_split_node: the CPU's node numbers).
struct Hlbvh2Forest {
    std::vector<uint32_t> order;           // sorted position -> triangle (the stable 30-bit Morton order)
    std::vector<uint32_t> refs;            // 2 (n - 1) child references per inner node index, then one root per cluster
    std::vector<uint32_t> cluster_begin;   // clusters + 1: first sorted position of each cluster, then n
    std::vector<uint32_t> cluster_prefix;  // clusters: the 15-bit Morton prefix of each cluster
    // The top level, when built elsewhere: 2 child references per top node k
    // (2 k + side; top node k is node n - 1 + k, numbered by cluster ranges
    // as hlbvh2_top_steps.h says), 2 (clusters - 1) in all. Empty: the host
    // builds it.
    std::vector<uint32_t> top_refs;
};

// The CPU's top level over `clusters` (reordered in place by its stable
// partitions): 2 (clusters - 1) child references as Hlbvh2Forest::top_refs,
// top node k being node top_base + k; empty for fewer than 2 clusters.
std::vector<uint32_t> build_hlbvh2_top_level(std::span<hlbvh2::TopCluster> clusters, uint32_t top_base);

// Finalizes every bottom node (box, count, SAH cost, leaf collapse) from
// the cluster roots down, builds the top level over the clusters (or checks
// and takes forest.top_refs) and finalizes it, and emits the canonical BVH.
// Throws rf::Error when the forest is malformed (a child outside its
// parent's range, a leaf not at its range's start, a leaf over
// max_leaf_size, a top level that is not a tree over the cluster roots).
// stages->top_ms (the top level) and ->emit_ms (the bottom refit and the
// emission) are set when stages is given; nothing else.
Bvh emit_hlbvh2_forest(std::span<const Triangle> triangles, const BvhBuildConfig& config, Hlbvh2Forest&& forest,
                       Hlbvh2Stages* stages = nullptr);

}  // namespace rf
