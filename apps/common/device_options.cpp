#include "device_options.h"

#include "option_binding.h"
#include "rayforge/core/error.h"

namespace rf::cli {

CLI::Validator device_validator() { return parsed_by(parse_device, "cpu|cuda|cuda:N"); }

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

CLI::Option* add_device_option(CLI::App* cmd, Device& device, const std::string& help) {
    return cmd
        ->add_option_function<std::string>(
            "--device", [&device](const std::string& name) { device = parse_device(name); }, help)
        ->check(device_validator());
}

CLI::Option* add_gpu_kernel_option(CLI::App* cmd, BuildOptions& build) {
    return cmd
        ->add_option_function<std::string>(
            "--gpu-kernel", [&build](const std::string& name) { build.gpu_kernel = parse_gpu_kernel(name); },
            "GPU traversal kernel with --device cuda: bvh2 | aila-laine | aila-laine-fma | cwbvh | cwbvh-fma | "
            "kd-short-stack | kd-restart | "
            "grid | grid-proximity (default " + to_string(kDefaultGpuKernel) + " for a bvh, else the structure's "
            "own); the structure is built with the --builder / --grid-res options")
        ->check(gpu_kernel_validator());
}

CLI::Option* add_build_on_option(CLI::App* cmd, bool& build_on_device) {
    return cmd
        ->add_option_function<std::string>(
            "--build-on", [&build_on_device](const std::string& where) { build_on_device = where == "device"; },
            "With --device cuda: where the structure is built, device (default: the device builders lbvh30, "
            "lbvh63, hlbvh2, ploc, hploc, gridbvh, gridbvh-split and uniform grids, and the layout conversions; other "
            "builders run on the CPU) or host (everything on the CPU, then uploaded)")
        ->check(CLI::IsMember({"device", "host"}));
}

void check_build_on(const CLI::App* cmd, const Device& device) {
    if (cmd->count("--build-on") > 0 && !device.is_cuda()) throw Error("--build-on: needs --device cuda");
}

void require_usable(const Device& device) {
    try {
        require_device(device);
    } catch (const Error& e) {
        throw Error(std::string("--device ") + e.what());  // "--device cuda:1: no such device ..."
    }
}

}  // namespace rf::cli
