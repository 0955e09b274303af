// Scheduling of the cwbvh-fma kernel (GpuKernel::CwbvhFma): its trace
// launch and its persistent grid size, called by device_tracer.cu.
#pragma once

#include <cstdint>
#include <vector>

#include "backend/cuda/device_tracer_impl.h"

namespace rf::cuda {

// Traces `count` rays of t.rays into t.hits (closest hit) or t.flags (any hit) on t.stream.
void launch_cwbvh_fma_trace(const DeviceTracer::Impl& impl, bool any_hit, uint32_t count, const TraceTarget& t);

// Resident blocks per multiprocessor of the persistent kernel at the trace block size.
int cwbvh_fma_blocks_per_sm(bool any_hit);

// The persistent kernels' registers, local and shared memory and occupancy (the bench's resource lines).
std::vector<GpuKernelResources> cwbvh_fma_kernel_resources(int device);

}  // namespace rf::cuda
