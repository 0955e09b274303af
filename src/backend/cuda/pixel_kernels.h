// The per-pixel kernel of the integrators that need no wavefront (Whitted,
// AO, normals): one thread per pixel runs render/pixel_sample.h, the CPU
// renderer's own per-pixel function, on the chosen tracer, counting its
// closest-hit and shadow queries. Its instantiations are the heaviest code
// of the backend (Whitted's explicit ray stack, every material and light),
// so they are compiled in two translation units (pixel_kernels_bvh.cu,
// pixel_kernels_cells.cu) that a parallel build runs side by side.
#pragma once

#include <cuda_runtime.h>

#include "backend/cuda/device_tracer_impl.h"
#include "backend/cuda/launch.h"
#include "render/counting_tracer.h"
#include "render/pixel_sample.h"
#include "render/scene_view.h"

namespace rf::cuda {

// What one pass of the pixel kernel reads.
struct PixelPass {
    SceneView view;
    IntegratorSettings settings;
    uint32_t sample = 0;
    Films films;
    unsigned long long* ray_counts = nullptr;  // [closest, shadow], added to
};

// One sample per pixel, then the block's ray counts summed in shared
// memory: one global atomic per block.
template <class Tracer>
__global__ void pixel_kernel(Tracer tracer, PixelPass p) {
    __shared__ unsigned int block_rays[2];
    if (threadIdx.x < 2) block_rays[threadIdx.x] = 0;
    __syncthreads();
    const uint32_t pixel = blockIdx.x * blockDim.x + threadIdx.x;
    uint32_t closest = 0, shadow = 0;
    if (pixel < uint32_t(p.settings.width) * uint32_t(p.settings.height)) {
        const CountingTracer<Tracer, uint32_t> counted{tracer, &closest, &shadow};
        add_pixel_sample<false>(counted, p.view, p.settings, p.sample, pixel, p.films);
    }
    if (closest) atomicAdd(&block_rays[0], closest);
    if (shadow) atomicAdd(&block_rays[1], shadow);
    __syncthreads();
    if (threadIdx.x < 2 && block_rays[threadIdx.x])
        atomicAdd(&p.ray_counts[threadIdx.x], (unsigned long long)block_rays[threadIdx.x]);
}

// Launches pixel_kernel with impl's tracer: the BVH tracers' instantiations
// live in pixel_kernels_bvh.cu, the kd-tree and grid ones in
// pixel_kernels_cells.cu. Checks the launch.
void launch_pixel_kernel(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape);
void launch_pixel_kernel_bvh(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape);
void launch_pixel_kernel_cells(const DeviceTracer::Impl& impl, const PixelPass& p, const LaunchShape& shape);

}  // namespace rf::cuda
