// One camera sample per pixel for each integrator, on the device: the
// per-sample code of src/render (integrators, BSDF, light sampling, texture
// filtering) compiled by nvcc as it is for the CPU. The host side that fills
// a DeviceSceneView and launches these (the wavefront path tracer and the
// progressive mode) is the CUDA renderer's; until it lands these kernels are
// compiled, not launched, which keeps every per-sample header device-clean
// in CI.
#include <cuda_runtime.h>

#include "backend/cuda/device_scene_view.h"
#include "rayforge/scene/camera.h"
#include "render/integrators/ao.h"
#include "render/integrators/normals.h"
#include "render/integrators/path.h"
#include "render/integrators/whitted.h"

namespace rf::cuda {

struct SampleKernelParams {
    DeviceSceneView view;
    DeviceBvhTracer tracer;
    CameraFrame camera;
    int width = 0, height = 0;
    uint32_t sample = 0, seed = 0;
    int integrator = 0;  // rf::IntegratorKind
    PathSettings path;
    WhittedSettings whitted;
    AoSettings ao;
    Vec3f* film = nullptr;  // accumulated sums, width * height
};

__global__ void render_sample_kernel(SampleKernelParams p) {
    const int x = int(blockIdx.x * blockDim.x + threadIdx.x), y = int(blockIdx.y * blockDim.y + threadIdx.y);
    if (x >= p.width || y >= p.height) return;
    const uint32_t pixel = uint32_t(y) * uint32_t(p.width) + uint32_t(x);
    RandomStream rng(pixel, p.sample, p.seed);
    const Vec2f jitter = rng.next2();
    const Vec2f lens = rng.next2();
    const Ray ray = p.camera.generate(float(x) + jitter.x, float(y) + jitter.y, p.width, p.height, lens.x, lens.y);
    Vec3f value;
    switch (p.integrator) {
        case 0: value = normals_radiance(p.tracer, p.view, ray); break;
        case 1: value = ao_radiance(p.tracer, p.view, ray, rng, p.ao); break;
        case 2: value = whitted_radiance(p.tracer, p.view, ray, rng, p.whitted); break;
        default: value = path_radiance(p.tracer, p.view, ray, rng, p.path); break;
    }
    if (!is_finite(value)) value = Vec3f(0.0f);
    p.film[pixel] += value;
}

}  // namespace rf::cuda
