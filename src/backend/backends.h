// The device seam: what each backend gives the engine. The public entry
// points (rf::build_accel, rf::build_bvh, rf::make_renderer,
// rf::list_cuda_devices, rf::require_device, rf::register_gl_pixel_buffer) pick the backend from an
// rf::Device and call these; nothing else in the library, the bench or the
// apps names a backend. The CUDA functions are defined by src/backend/cuda,
// or, in a build without it, by backend/cuda_unavailable.cpp, where each
// answers with the one "built without the CUDA backend" error.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/build_report.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/render/display.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"

namespace rf {

// The reason every CUDA request fails in a build without the backend.
inline constexpr const char* kCudaNotBuilt =
    "this rayforge was built without the CUDA backend (nvcc was not found at configure time)";

namespace cpu {

// `progress` sees the fraction of a BVH build (the top-down SAH builders
// count references placed in leaves); other structures report nothing.
std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options,
                                   const ProgressCallback& progress = {});
// A renderer for an in-core world on the CPU.
std::unique_ptr<Renderer> make_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                        const RenderOptions& options);
// A renderer for a paged world (ooc/paged_renderer.cpp).
std::unique_ptr<Renderer> make_paged_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                              const RenderOptions& options);

}  // namespace cpu

namespace cuda {

bool backend_built();
DeviceListing list_devices();
// Throws rf::Error when device `index` cannot be used.
void require_device(int index);
// The structure options.gpu_kernel traverses, on device options.device.index.
std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options);
// options.builder run by its device builder (rf::Error for a builder without one).
Bvh build_bvh(std::span<const Triangle> triangles, const BuildOptions& options, BuildReport* report);
// A structure on device build.device.index kept current over an animation
// with update.method refit, rebuild or two-level (rf::Error for the others).
std::unique_ptr<DynamicAccel> build_dynamic_accel(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build, const UpdateOptions& update);
// A renderer for an in-core world on a CUDA device (its structures are cuda::build_accel's).
std::unique_ptr<Renderer> make_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                        const RenderOptions& options);
// OpenGL buffer `gl_buffer` of the current context registered on device `index`.
std::unique_ptr<GlPixelBuffer> register_gl_pixel_buffer(int index, unsigned int gl_buffer);
// rf::gpu_kernel_resources on a CUDA device (backend/cuda/kernel_resources.cu).
std::vector<GpuKernelResources> gpu_kernel_resources(GpuKernel kernel, const Device& device);

}  // namespace cuda
}  // namespace rf
