// On a CUDA device a structure is built for the GPU kernel that traverses
// it, so BuildOptions::structure and BuildOptions::gpu_kernel must agree.
// The rule, for build_accel and for worlds: whichever of the two is not its
// default (bvh; rf::kDefaultGpuKernel) decides the other: a grid kernel
// builds a grid, a kd-tree is traced by kd-short-stack unless a kd-tree
// kernel is named; both named and disagreeing is an rf::Error, and so is a
// structure no kernel traverses (brute force). The CPU ignores gpu_kernel.
#pragma once

#include "rayforge/accel/accel.h"

namespace rf {

// `options` with the structure and the kernel agreeing on options.device.
BuildOptions with_device_structure(BuildOptions options);

}  // namespace rf
