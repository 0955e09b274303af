// What a compiled kernel costs a multiprocessor (registers, local memory,
// shared memory) and how many of its blocks fit there at a launch's block
// size: CUDA's function attributes and occupancy calculator, the figures
// Nsight Compute's Launch Statistics and Occupancy sections show, read
// without a profiler. The bench prints them per trace kernel
// (rf::gpu_kernel_resources, rayforge/backend/device.h).
#pragma once

#include <string>

#include "backend/backends.h"

namespace rf::cuda {

// The resources of kernel `function` (a __global__ function's address)
// launched with `block_size` threads and `dynamic_shared_bytes` of dynamic
// shared memory per block, on device `device` (made current). rf::Error when
// CUDA refuses.
GpuKernelResources kernel_resources_of(const void* function, const std::string& name, int block_size, int device,
                                       size_t dynamic_shared_bytes = 0);

}  // namespace rf::cuda
