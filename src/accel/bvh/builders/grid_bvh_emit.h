// The host half of a GridBvh / GridBvhSplit built elsewhere (the CUDA
// builder, backend/cuda/grid_bvh_build.cu; Garanzha 2014, dissertation ch. 4):
// given the references and the grid hierarchy of EmitHierarchy (Algorithm
// 4.1), the CPU builder's own leaf finishing (reference shuffling, merging
// of parts, splitting of leaves over max_leaf_size) and canonical emission
// give rf::build_grid_bvh's BVH. The device finishes and emits by itself
// (grid_bvh_finish_steps.h) unless a leaf holds more than
// gridbvh::kDeviceFinishRefs references; then it hands over here.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/grid_bvh_steps.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// A grid hierarchy as the split tasks leave it. Nodes are numbered level by
// level: the children of level l are node pairs (left, left + 1) of level
// l + 1; the order of pairs within a level and of the leaves is free (the
// emission does not depend on it).
struct GridHierarchy {
    gridbvh::GridFrame frame;              // the scene box's Grid0 frame
    std::vector<gridbvh::GridRef> refs;    // the references (after splitting), in reference order
    std::vector<uint32_t> hnodes;          // per node: its left child, or kLeafBit | leaf index
    std::vector<gridbvh::NodeRegion> regions;  // per node: its IBB at creation (the root's: Grid7)
    std::vector<gridbvh::SplitTask> leaves;    // per leaf: its (refined) task; depth is used
    std::vector<uint32_t> level_offset;    // first node of each tree level, plus the node count
    // Optional (empty: the host groups them): the references grouped by leaf
    // (leaf_of_reference), ascending within a leaf, and each leaf's first
    // position in leaf_refs plus the end.
    std::vector<uint32_t> leaf_refs;
    std::vector<uint32_t> leaf_begin;
};

// Finishes the leaves and emits the canonical BVH, as build_grid_bvh does
// after its own hierarchy. stages->leaf_finish_ms, emission_ms, references
// and hierarchy_leaves are set. Throws rf::Error for a malformed hierarchy
// (links outside the next level, leaves out of range, malformed leaf groups).
Bvh emit_grid_bvh_hierarchy(std::span<const Triangle> triangles, const BvhBuildConfig& config, bool partial_triangles,
                            GridHierarchy&& hierarchy, GridBvhStages* stages = nullptr);

}  // namespace rf
