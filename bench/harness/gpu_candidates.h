// Which GPU kernel traces which structure in the bench. The kernels of a
// structure trace what the CPU candidates of that structure build (bvh2,
// aila-laine and cwbvh trace BVHs; kd-short-stack and kd-restart kd-trees;
// grid and grid-proximity their grids), so `--builder sbvh --device cuda`
// traces SBVH trees on the device and a seed preset's grids keep their
// resolutions. CUDA-free: the rows are planned the same way in every build.
#pragma once

#include <string>
#include <vector>

#include "candidates.h"
#include "rayforge/backend/device.h"

namespace rf::bench {

// The structure a kernel traverses: "bvh", "kdtree", "grid" or "grid-proximity".
std::string gpu_kernel_structure(GpuKernel kernel);

// One GPU row: a kernel and the CPU-built structure it traces.
struct GpuCandidate {
    GpuKernel kernel = kDefaultGpuKernel;
    Candidate build;  // structure, builder and options of the build; layout = the kernel's name

    [[nodiscard]] std::string label() const { return build.label(); }  // e.g. "bvh/binned/cwbvh"
};

// For each kernel, one row per distinct (structure, builder) among
// `candidates` of the kernel's structure, in their order; a kernel whose
// structure no candidate has gets the catalogue's default build of it (bvh:
// the default builder; grids: uniform-auto; kdtree: sah).
std::vector<GpuCandidate> gpu_candidates(const std::vector<GpuKernel>& kernels,
                                         const std::vector<Candidate>& candidates);

}  // namespace rf::bench
