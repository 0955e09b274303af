// Device and GPU-kernel names, and the device queries of rayforge/backend/device.h.
#include "rayforge/backend/device.h"

#include <cstdlib>
#include <utility>

#include "backend/backends.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

constexpr std::pair<const char*, GpuKernel> kKernelNames[] = {
    {"bvh2", GpuKernel::Bvh2},
    {"aila-laine", GpuKernel::AilaLaine},
    {"aila-laine-fma", GpuKernel::AilaLaineFma},
    {"cwbvh", GpuKernel::Cwbvh},
    {"cwbvh-fma", GpuKernel::CwbvhFma},
    {"kd-short-stack", GpuKernel::KdShortStack},
    {"kd-restart", GpuKernel::KdRestart},
    {"grid", GpuKernel::Grid},
    {"grid-proximity", GpuKernel::ProximityGrid},
};

}  // namespace

Device parse_device(const std::string& name) {
    if (name == "cpu") return {Device::Kind::Cpu, 0};
    if (name == "cuda") return {Device::Kind::Cuda, 0};
    if (name.rfind("cuda:", 0) == 0 && name.size() > 5 && name.size() <= 8) {
        const std::string digits = name.substr(5);
        bool all_digits = true;
        for (char c : digits) all_digits = all_digits && c >= '0' && c <= '9';
        if (all_digits) return {Device::Kind::Cuda, std::atoi(digits.c_str())};
    }
    throw Error("unknown device '" + name + "' (expected cpu, cuda or cuda:N)");
}

std::string to_string(const Device& device) {
    return device.is_cuda() ? "cuda:" + std::to_string(device.index) : "cpu";
}

GpuKernel parse_gpu_kernel(const std::string& name) {
    for (const auto& [text, kernel] : kKernelNames)
        if (name == text) return kernel;
    std::string known;
    for (const auto& [text, kernel] : kKernelNames) known += (known.empty() ? "" : ", ") + std::string(text);
    throw Error("unknown GPU kernel '" + name + "' (expected one of: " + known + ")");
}

std::string to_string(GpuKernel kernel) {
    for (const auto& [text, k] : kKernelNames)
        if (k == kernel) return text;
    return "?";
}

std::vector<GpuKernel> all_gpu_kernels() {
    std::vector<GpuKernel> kernels;
    for (const auto& [text, kernel] : kKernelNames) kernels.push_back(kernel);
    return kernels;
}

bool cuda_backend_built() { return cuda::backend_built(); }

DeviceListing list_cuda_devices() { return cuda::list_devices(); }

void require_device(const Device& device) {
    if (device.is_cuda()) cuda::require_device(device.index);
}

}  // namespace rf
