// rf::gpu_kernel_resources (rayforge/backend/device.h): the device seam's
// entry for the bench's per-kernel register, local-memory and occupancy
// lines; the CUDA backend answers (backend/cuda/kernel_resources.cu).
#include "backend/backends.h"
#include "rayforge/core/error.h"

namespace rf {

std::vector<GpuKernelResources> gpu_kernel_resources(GpuKernel kernel, const Device& device) {
    if (!device.is_cuda()) throw Error("gpu_kernel_resources: " + to_string(device) + " is not a CUDA device");
    return cuda::gpu_kernel_resources(kernel, device);
}

}  // namespace rf
