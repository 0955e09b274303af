// Instantiations of pixel_kernels.h's per-pixel kernel for the kd-tree and
// grid tracers (kd-short-stack, kd-restart, grid, grid-proximity).
#include "backend/cuda/pixel_kernels.h"

namespace rf::cuda {

void launch_pixel_kernel_cells(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape) {
    using ShortStack = KdTracer<KdTraversal::ShortStack>;
    using Restart = KdTracer<KdTraversal::Restart>;
    switch (impl.kernel) {
        case GpuKernel::KdShortStack: launch_shaped(pixel_kernel<ShortStack>, shape, impl.kd_short_stack, p); break;
        case GpuKernel::KdRestart: launch_shaped(pixel_kernel<Restart>, shape, impl.kd_restart, p); break;
        case GpuKernel::Grid:
        case GpuKernel::ProximityGrid: launch_shaped(pixel_kernel<GridTracer>, shape, impl.grid, p); break;
        default: throw Error("launch_pixel_kernel_cells: not a kd-tree or grid kernel");
    }
}

}  // namespace rf::cuda
