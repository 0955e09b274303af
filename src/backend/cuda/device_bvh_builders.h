// The BVH builders on the CUDA device, one per CPU builder that has a device
// version. Each takes what its CPU counterpart takes (the leaf size and SAH
// costs of BvhBuildConfig, and its own options group) and gives the same BVH;
// build_bvh_on_device (backend/cuda/device_builders.h) dispatches to them, as
// build_bvh does on the CPU.
//
// `resident` (device_bvh.h; LBVH, HLBVH2, PLOC, H-PLOC): when given and the
// device emitted the tree, the canonical BVH stays in *resident and the
// returned Bvh is empty (no download); when the host emitted it (too deep,
// fewer than 2 triangles), *resident stays empty and the Bvh is returned.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "rayforge/accel/bvh/bvh.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

struct DeviceBvh;

// LBVH (Karras 2012) on device `device`: the same BVH as rf::build_lbvh with
// the same config and Morton bits (30 or 63): same nodes, same primitive
// order. The device computes boxes, codes, the sort, the radix tree and its
// boxes, then collapses leaves by the SAH and writes the canonical layout
// (the host does the last two when the tree is deeper than kBvhMaxDepth).
// Throws rf::Error for invalid bits or CUDA failures (out of memory names the buffer).
Bvh build_lbvh_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config, int morton_bits,
                         DeviceBuildStages* stages = nullptr, int device = 0, DeviceBvh* resident = nullptr);

// HLBVH2 (Garanzha, Pantaleoni and McAllister 2011; Garanzha 2014 ch. 5) on
// device `device`: the same BVH as rf::build_hlbvh2 with the same config.
// The device sorts 30-bit codes once, compacts the 15-bit clusters, builds
// the bottom levels by work queues and the top level over the clusters by
// task queues (the grid SAH of ch. 4 on the top grid, 8 threads per task),
// with the boxes of every level, then the leaf collapse and the canonical
// layout (the host does those when the tree is deeper than kBvhMaxDepth,
// and checks the forest then). 0 and 1 triangles are handled on the host. Throws
// rf::Error for CUDA failures (out of memory names the buffer).
Bvh build_hlbvh2_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                           DeviceBuildStages* stages = nullptr, int device = 0, DeviceBvh* resident = nullptr);

// PLOC (Meister and Bittner 2018) on device `device`: the same BVH as
// rf::build_ploc with the same config and radius.
Bvh build_ploc_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                         const PlocOptions& ploc_options, DeviceBuildStages* stages = nullptr, int device = 0,
                         DeviceBvh* resident = nullptr);

// H-PLOC (Benthin et al. 2024) on device `device`: the same BVH as
// rf::build_hploc with the same config and radius (clamped to 1 .. 31). One
// launch after the sort builds the whole clustering (hploc_build.cu).
Bvh build_hploc_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                          const PlocOptions& ploc_options, DeviceBuildStages* stages = nullptr, int device = 0,
                          DeviceBvh* resident = nullptr);

// GridBvh, or GridBvhSplit with `partial_triangles` (Garanzha 2014 ch. 4), on
// device `device`: the same BVH as rf::build_grid_bvh with the same config
// and options; GridBvhSplit adds at most floor(grid_bvh.split_budget *
// triangles) references.
Bvh build_grid_bvh_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                             const GridBvhOptions& grid_bvh, bool partial_triangles,
                             DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
