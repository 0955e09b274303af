// Internal face of the device emission of Morton-family raw trees
// (raw_tree_emit.cu; the steps are accel/bvh/builders/raw_tree_emit_steps.h):
// the LBVH, HLBVH2 and PLOC device builders hand over the tree they left in
// device memory and get the canonical BVH back, leaf collapse and layout
// done on the device.
#pragma once

#include <cstdint>
#include <string>

#include "accel/bvh/builders/bvh_build_config.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/math/box.h"

namespace rf::cuda {

// Device pointers; see raw_emit::RawTreeView for the encoding.
struct DeviceRawTree {
    const uint32_t* children = nullptr;       // 2 per node slot below high_base (unused slots: kNoChild)
    const uint32_t* high_children = nullptr;  // 2 per node slot from high_base on
    uint32_t high_base = 0;
    uint32_t node_slots = 0;
    uint32_t root = 0;                        // reference
    uint32_t primitives = 0;                  // n >= 2
    const Box3f* boxes = nullptr;
    bool boxes_by_triangle = true;
    const uint32_t* order = nullptr;
    const uint8_t* leaf_runs = nullptr;       // null: every leaf one primitive
    // Most node slots unused (HLBVH2 numbers a node by its split position):
    // node values are then stored for the used slots only, through a prefix
    // sum of the used ones.
    bool sparse_slots = false;
    // Parent links the builder already has (LBVH): both or neither. The
    // emitter scatters its own otherwise.
    const uint32_t* node_parent = nullptr;
    const uint32_t* leaf_parent = nullptr;
};

// Finalizes every node (box, count, SAH cost, leaf collapse) and writes the
// canonical BVH into `out`: RawTree::emit's result for the same tree.
// Returns false, with `out` untouched, when the emitted tree would be deeper
// than kBvhMaxDepth: the caller then emits on the host, whose depth-limited
// rebuild this emitter does not do. Adds the device time to
// build.stages.device_emit_ms and the download to download_ms; its buffers
// (named after `label`) are counted by build.meter and freed on return.
// With build.resident set, the BVH stays on the device there and `out` is
// left empty (no download).
bool emit_raw_tree_on_device(const DeviceRawTree& tree, const BvhBuildConfig& config, const std::string& label,
                             BuildContext& build, Bvh& out);

}  // namespace rf::cuda
