// Instantiations of pixel_kernels.h's per-pixel kernel for the BVH tracers
// (bvh2, aila-laine, cwbvh, their -fma variants, two-level), and the dispatch over all tracers.
#include "backend/cuda/pixel_kernels.h"

namespace rf::cuda {

void launch_pixel_kernel(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape) {
    switch (impl.kernel) {
        case GpuKernel::Bvh2:
        case GpuKernel::AilaLaine:
        case GpuKernel::AilaLaineFma:
        case GpuKernel::Cwbvh:
        case GpuKernel::CwbvhFma: launch_pixel_kernel_bvh(impl, p, shape); break;
        case GpuKernel::KdShortStack:
        case GpuKernel::KdRestart:
        case GpuKernel::Grid:
        case GpuKernel::ProximityGrid: launch_pixel_kernel_cells(impl, p, shape); break;
    }
}

void launch_pixel_kernel_bvh(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape) {
    if (impl.two_level) {
        launch_shaped(pixel_kernel<TwoLevelBvh2Tracer>, shape, impl.two_level->tracer(), p);
        return;
    }
    switch (impl.kernel) {
        case GpuKernel::Bvh2: launch_shaped(pixel_kernel<Bvh2Tracer>, shape, impl.bvh2, p); break;
        case GpuKernel::AilaLaine: launch_shaped(pixel_kernel<AilaLaineTracer>, shape, impl.aila_laine, p); break;
        case GpuKernel::AilaLaineFma:
            launch_shaped(pixel_kernel<AilaLaineFmaTracer>, shape, impl.aila_laine_fma, p);
            break;
        case GpuKernel::Cwbvh: launch_shaped(pixel_kernel<CwbvhTracer>, shape, impl.cwbvh, p); break;
        case GpuKernel::CwbvhFma: launch_shaped(pixel_kernel<CwbvhFmaTracer>, shape, impl.cwbvh_fma, p); break;
        default: throw Error("launch_pixel_kernel_bvh: not a BVH kernel");
    }
}

}  // namespace rf::cuda
