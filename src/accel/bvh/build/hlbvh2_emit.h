// The canonical BVH of HLBVH2 bottom trees built elsewhere (the CUDA
// HLBVH2, backend/cuda/hlbvh2_build.cu, by work queues): the host half of
// the device build. The top level over the clusters is built here by the
// CPU builder's own grid SAH (hlbvh2.cpp), so the result is build_hlbvh2's.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/build/hlbvh2.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// The bottom levels as hlbvh2_tasks.h's process_task leaves them.
struct Hlbvh2Forest {
    std::vector<uint32_t> order;           // sorted position -> triangle (the stable 30-bit Morton order)
    std::vector<uint32_t> refs;            // 2 (n - 1) child references per inner node index, then one root per cluster
    std::vector<uint32_t> cluster_begin;   // clusters + 1: first sorted position of each cluster, then n
    std::vector<uint32_t> cluster_prefix;  // clusters: the 15-bit Morton prefix of each cluster
};

// Finalizes every bottom node (box, count, SAH cost, leaf collapse) from
// the cluster roots down, builds the top level over the clusters and emits
// the canonical BVH. Throws rf::Error when the forest is malformed (a child
// outside its parent's range, a leaf not at its range's start, a leaf over
// max_leaf_size). stages->top_ms (the top level) and ->emit_ms (the bottom
// refit and the emission) are set when stages is given; nothing else.
Bvh emit_hlbvh2_forest(std::span<const Triangle> triangles, const BuildOptions& options, Hlbvh2Forest&& forest,
                       Hlbvh2Stages* stages = nullptr);

}  // namespace rf
