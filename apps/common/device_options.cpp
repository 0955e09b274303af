#include "device_options.h"

#include "rayforge/core/error.h"

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

void add_build_on_option(CLI::App* cmd, std::string& value) {
    cmd->add_option("--build-on", value,
                    "With --device cuda: where the structure is built, device (default: the device builders lbvh30, "
                    "lbvh63, hlbvh2, ploc, gridbvh, gridbvh-split and uniform grids, and the layout conversions; other "
                    "builders run on the CPU) or host (everything on the CPU, then uploaded)")
        ->check(CLI::IsMember({"device", "host"}));
}

bool parse_build_on(const std::string& value, bool cuda_device) {
    if (!value.empty() && !cuda_device) throw Error("--build-on: needs --device cuda");
    return value != "host";
}

void require_usable(const Device& device, const std::string& option) {
    try {
        require_device(device);
    } catch (const Error& e) {
        throw Error(option + ": " + e.what());
    }
}

}  // namespace rf::cli
