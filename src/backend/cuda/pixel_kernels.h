// The per-pixel kernel of the integrators that need no wavefront (Whitted,
// AO, normals): one thread per pixel runs the CPU renderer's per-sample
// functions (src/render/integrators) on the chosen tracer, counting its
// closest-hit and shadow queries. Its instantiations are the heaviest code
// of the backend (Whitted's explicit ray stack, every material and light),
// so they are compiled in two translation units (pixel_kernels_bvh.cu,
// pixel_kernels_cells.cu) that a parallel build runs side by side.
#pragma once

#include <cuda_runtime.h>

#include "backend/cuda/device_scene.h"
#include "backend/cuda/device_tracer_impl.h"
#include "render/integrators/ao.h"
#include "render/integrators/normals.h"
#include "render/integrators/path.h"
#include "render/integrators/whitted.h"

namespace rf::cuda {

struct Films {
    Vec3f* color = nullptr;
    Vec3f* albedo = nullptr;
    Vec3f* normal = nullptr;
    Vec3f* depth = nullptr;
};

// The integrators' tracer with a count of the closest-hit and shadow queries
// it answers, like the CPU's AccelTracer, so GPU rows report the same rays.
template <class Tracer>
struct RayCountingTracer {
    const Tracer& tracer;
    uint32_t* closest;
    uint32_t* shadow;
    __device__ Hit intersect(const Ray& ray) const {
        ++*closest;
        return tracer.intersect(ray);
    }
    __device__ bool occluded(const Ray& ray) const {
        ++*shadow;
        return tracer.occluded(ray);
    }
};

struct PixelKernelParams {
    DeviceSceneView view;
    CameraFrame camera;
    int width = 0, height = 0;
    uint32_t sample = 0, seed = 0;
    bool centre = false;  // one sample at the pixel centre (Whitted and normals at 1 spp)
    int integrator = 0;   // rf::IntegratorKind
    WhittedSettings whitted;
    AoSettings ao;
    float clamp = 0.0f;
    Films films;
    unsigned long long* ray_counts = nullptr;  // [closest, shadow], added to
};

template <class Tracer>
__device__ void pixel_sample(const Tracer& tracer, const PixelKernelParams& p, uint32_t pixel) {
    const int x = int(pixel % uint32_t(p.width)), y = int(pixel / uint32_t(p.width));
    RandomStream rng(pixel, p.sample, p.seed);
    const Vec2f jitter = p.centre ? Vec2f{0.5f, 0.5f} : rng.next2();
    const Vec2f lens = rng.next2();
    const Ray ray = p.camera.generate(float(x) + jitter.x, float(y) + jitter.y, p.width, p.height, lens.x, lens.y);
    Vec3f value;
    switch (p.integrator) {
        case int(IntegratorKind::Normals): value = normals_radiance(tracer, p.view, ray); break;
        case int(IntegratorKind::AmbientOcclusion): value = ao_radiance(tracer, p.view, ray, rng, p.ao); break;
        default: value = whitted_radiance(tracer, p.view, ray, rng, p.whitted); break;
    }
    p.films.color[pixel] += film_sample(value, p.clamp);
    if (p.films.albedo) {
        const FirstHitAovs a = first_hit_aovs(tracer, p.view, ray);
        p.films.albedo[pixel] += a.albedo;
        p.films.normal[pixel] += a.normal;
        p.films.depth[pixel] += Vec3f(a.depth);
    }
}

// One sample per pixel of the integrators that need no wavefront, then the
// block's ray counts summed in shared memory: one global atomic per block.
template <class Tracer>
__global__ void pixel_kernel(Tracer tracer, PixelKernelParams p) {
    __shared__ unsigned int block_rays[2];
    if (threadIdx.x < 2) block_rays[threadIdx.x] = 0;
    __syncthreads();
    const uint32_t pixel = blockIdx.x * blockDim.x + threadIdx.x;
    uint32_t closest = 0, shadow = 0;
    if (pixel < uint32_t(p.width) * uint32_t(p.height))
        pixel_sample(RayCountingTracer<Tracer>{tracer, &closest, &shadow}, p, pixel);
    if (closest) atomicAdd(&block_rays[0], closest);
    if (shadow) atomicAdd(&block_rays[1], shadow);
    __syncthreads();
    if (threadIdx.x < 2 && block_rays[threadIdx.x]) atomicAdd(&p.ray_counts[threadIdx.x], (unsigned long long)block_rays[threadIdx.x]);
}

// Launches pixel_kernel with impl's tracer: the BVH tracers' instantiations
// live in pixel_kernels_bvh.cu, the kd-tree and grid ones in
// pixel_kernels_cells.cu. Checks the launch.
void launch_pixel_kernel(const DeviceTracer::Impl& impl, const PixelKernelParams& p, int blocks, int block_size);
void launch_pixel_kernel_bvh(const DeviceTracer::Impl& impl, const PixelKernelParams& p, int blocks, int block_size);
void launch_pixel_kernel_cells(const DeviceTracer::Impl& impl, const PixelKernelParams& p, int blocks, int block_size);

}  // namespace rf::cuda
