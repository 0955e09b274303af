#include "device_options.h"

#include "rayforge/core/error.h"

#ifdef RAYFORGE_HAS_CUDA
#include "rayforge/backend/cuda.h"
#endif

namespace rf::cli {

CLI::Validator device_validator() {
    return CLI::Validator(
        [](std::string& name) {
            try {
                parse_device(name);
                return std::string();
            } catch (const Error& e) {
                return std::string(e.what());
            }
        },
        "cpu|cuda|cuda:N");
}

CLI::Validator gpu_kernel_validator(bool allow_all) {
    return CLI::Validator(
        [allow_all](std::string& name) {
            if (allow_all && name == "all") return std::string();
            try {
                parse_gpu_kernel(name);
                return std::string();
            } catch (const Error& e) {
                return std::string(e.what());
            }
        },
        "KERNEL");
}

void require_usable(const Device& device, const std::string& option) {
    if (!device.is_cuda()) return;
#ifdef RAYFORGE_HAS_CUDA
    try {
        cuda::require_device(device.index);
    } catch (const Error& e) {
        throw Error(option + ": " + e.what());
    }
#else
    throw Error(option + ": " + kNoCudaBackend);
#endif
}

}  // namespace rf::cli
