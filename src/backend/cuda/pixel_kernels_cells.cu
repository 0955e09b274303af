// Instantiations of pixel_kernels.h's per-pixel kernel for the kd-tree and
// grid tracers (kd-short-stack, kd-restart, grid, grid-proximity).
#include "backend/cuda/pixel_kernels.h"

namespace rf::cuda {

void launch_pixel_kernel_cells(const DeviceTracer::Impl& impl, const PixelPass& p, int blocks,
                               int block_size) {
    switch (impl.kernel) {
        case GpuKernel::KdShortStack: pixel_kernel<<<blocks, block_size>>>(impl.kd_short_stack, p); break;
        case GpuKernel::KdRestart: pixel_kernel<<<blocks, block_size>>>(impl.kd_restart, p); break;
        case GpuKernel::Grid:
        case GpuKernel::ProximityGrid: pixel_kernel<<<blocks, block_size>>>(impl.grid, p); break;
        default: throw Error("launch_pixel_kernel_cells: not a kd-tree or grid kernel");
    }
}

}  // namespace rf::cuda
