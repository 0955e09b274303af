// Instantiations of pixel_kernels.h's per-pixel kernel for the BVH tracers
// (bvh2, aila-laine, cwbvh), and the dispatch over all tracers.
#include "backend/cuda/cuda_check.h"
#include "backend/cuda/pixel_kernels.h"

namespace rf::cuda {

void launch_pixel_kernel(const DeviceTracer::Impl& impl, const PixelPass& p, int blocks, int block_size) {
    switch (impl.kernel) {
        case GpuKernel::Bvh2:
        case GpuKernel::AilaLaine:
        case GpuKernel::Cwbvh: launch_pixel_kernel_bvh(impl, p, blocks, block_size); break;
        case GpuKernel::KdShortStack:
        case GpuKernel::KdRestart:
        case GpuKernel::Grid:
        case GpuKernel::ProximityGrid: launch_pixel_kernel_cells(impl, p, blocks, block_size); break;
    }
    RF_CUDA_CHECK(cudaGetLastError());
}

void launch_pixel_kernel_bvh(const DeviceTracer::Impl& impl, const PixelPass& p, int blocks, int block_size) {
    switch (impl.kernel) {
        case GpuKernel::Bvh2: pixel_kernel<<<blocks, block_size>>>(impl.bvh2, p); break;
        case GpuKernel::AilaLaine: pixel_kernel<<<blocks, block_size>>>(impl.aila_laine, p); break;
        case GpuKernel::Cwbvh: pixel_kernel<<<blocks, block_size>>>(impl.cwbvh, p); break;
        default: throw Error("launch_pixel_kernel_bvh: not a BVH kernel");
    }
}

}  // namespace rf::cuda
