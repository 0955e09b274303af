// The CUDA half of the device seam (backend/backends.h) in a build without
// the CUDA backend: no devices, and one error for every request.
#include "backend/backends.h"
#include "backend/cuda/bvh_refit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {

bool backend_built() { return false; }
DeviceListing list_devices() { return {{}, kCudaNotBuilt}; }
void require_device(int index) { throw Error("cuda:" + std::to_string(index) + ": " + kCudaNotBuilt); }
std::unique_ptr<Accel> build_accel(const SceneGeometry&, const BuildOptions& options) {
    throw Error(to_string(options.device) + ": " + kCudaNotBuilt);
}
Bvh build_bvh(std::span<const Triangle>, const BuildOptions& options, BuildReport*) {
    throw Error(to_string(options.device) + ": " + kCudaNotBuilt);
}
std::unique_ptr<DynamicAccel> build_dynamic_accel(const Scene&, const SceneGeometry&, const BuildOptions& build,
                                                  const UpdateOptions&) {
    throw Error(to_string(build.device) + ": " + kCudaNotBuilt);
}
std::unique_ptr<Renderer> make_renderer(std::shared_ptr<WorldCore>, const Camera&, const RenderOptions&) {
    throw Error(kCudaNotBuilt);
}

std::unique_ptr<GlPixelBuffer> register_gl_pixel_buffer(int index, unsigned int) {
    throw Error("cuda:" + std::to_string(index) + ": " + kCudaNotBuilt);
}
std::vector<GpuKernelResources> gpu_kernel_resources(GpuKernel, const Device& device) {
    throw Error(to_string(device) + ": " + kCudaNotBuilt);
}

DeviceRefitTimes refit_bvh_on_device(Bvh&, std::span<const Triangle>, int, int device) {
    throw Error("cuda:" + std::to_string(device) + ": " + kCudaNotBuilt);
}
void compute_refit_parents_on_device(const BvhNode*, uint32_t, uint32_t*) { throw Error(kCudaNotBuilt); }
void refit_bvh_on_device(const DeviceRefitArrays&) { throw Error(kCudaNotBuilt); }
struct DeviceBvhRefit::Impl {};
DeviceBvhRefit::DeviceBvhRefit(const Bvh&, int device) {
    throw Error("cuda:" + std::to_string(device) + ": " + kCudaNotBuilt);
}
DeviceBvhRefit::~DeviceBvhRefit() = default;
double DeviceBvhRefit::refit(std::span<const Triangle>) { throw Error(kCudaNotBuilt); }
void DeviceBvhRefit::download(Bvh&) const { throw Error(kCudaNotBuilt); }
DeviceRefitArrays DeviceBvhRefit::arrays() const { throw Error(kCudaNotBuilt); }
size_t DeviceBvhRefit::bytes() const { return 0; }

}  // namespace rf::cuda
