// Per-kernel registers, local memory, shared memory and occupancy for the
// bench (kernel_resources.h). Occupancy is the theoretical one of the CUDA
// occupancy calculator: resident warps of the launch's block size over the
// multiprocessor's maximum (cudaOccupancyMaxActiveBlocksPerMultiprocessor,
// which accounts for registers, shared memory and the block limit); achieved
// occupancy needs a profiler (scripts/gpu-run.sh profile).
#include "backend/cuda/kernel_resources.h"

#include <cuda_runtime.h>

#include "backend/cuda/cuda_check.h"
#include "backend/cuda/device_tracer.h"

namespace rf::cuda {

GpuKernelResources kernel_resources_of(const void* function, const std::string& name, int block_size, int device,
                                       size_t dynamic_shared_bytes) {
    RF_CUDA_CHECK(cudaSetDevice(device));
    cudaFuncAttributes attributes{};
    RF_CUDA_CHECK(cudaFuncGetAttributes(&attributes, function));
    int blocks = 0;
    RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, function, block_size, dynamic_shared_bytes));
    int threads_per_sm = 0;
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&threads_per_sm, cudaDevAttrMaxThreadsPerMultiProcessor, device));
    GpuKernelResources r;
    r.kernel = name;
    r.registers = attributes.numRegs;
    r.local_bytes = attributes.localSizeBytes;
    r.shared_bytes = attributes.sharedSizeBytes + dynamic_shared_bytes;
    r.max_threads_per_block = attributes.maxThreadsPerBlock;
    r.block_size = block_size;
    r.blocks_per_sm = blocks;
    r.occupancy = threads_per_sm > 0 ? double(blocks) * double(block_size) / double(threads_per_sm) : 0.0;
    return r;
}

std::vector<GpuKernelResources> gpu_kernel_resources(GpuKernel kernel, const Device& device) {
    require_device(device.index);
    return trace_kernel_resources(kernel, device.index);
}

}  // namespace rf::cuda
