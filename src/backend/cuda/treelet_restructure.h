// Treelet restructuring on a CUDA device (treelet_restructure.cu; the steps
// are accel/bvh/optimize/treelet_restructure_steps.h, the CPU pass
// accel/bvh/optimize/treelet_restructure.cpp). No CUDA header is needed to
// include this.
#pragma once

#include <span>

#include "accel/bvh/builders/bvh_build_config.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// rf::optimize_treelets on device `device`: the same tree, bit for bit.
// `bvh` is on the host (the device builders download theirs), so its nodes,
// slots and triangles are uploaded and the result downloaded; adds the
// device time (rounds and emission, CUDA events) to stages->treelet_ms and
// the transfers to upload_ms and download_ms. Throws rf::Error as
// optimize_treelets does, and for CUDA failures.
void optimize_treelets_on_device(Bvh& bvh, std::span<const Triangle> triangles, const BvhBuildConfig& config,
                                 const TreeletOptions& options, DeviceBuildStages* stages = nullptr, int device = 0);

}  // namespace rf::cuda
