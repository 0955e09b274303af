// The one gate every device test goes through. Without a usable device a
// test skips, saying why in the runtime's words; with RAYFORGE_REQUIRE_GPU=1
// (scripts/gpu-run.sh sets it) it fails instead, so a GPU run whose runtime
// cannot reach the device (driver/runtime mismatch, missing device nodes, a
// sandbox refusing it) cannot read green having tested nothing.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/world.h"

namespace rf::gpu_test {

// Listed once per process: every test asks.
inline const DeviceListing& device_listing() {
    static const DeviceListing listing = list_cuda_devices();
    return listing;
}

// `options` for `kernel` on cuda:N: the kernel's structure, built there.
inline BuildOptions on_device(GpuKernel kernel, BuildOptions options = {}, int index = 0) {
    options.device = Device{Device::Kind::Cuda, index};
    options.gpu_kernel = kernel;
    options.structure = structure_of(kernel);
    return options;
}

// A world's options for `kernel` on cuda:N (the world builds the kernel's structure there).
inline WorldOptions world_on_device(GpuKernel kernel, int index = 0) {
    WorldOptions options;
    options.device = Device{Device::Kind::Cuda, index};
    options.build.gpu_kernel = kernel;
    return options;
}

// Set and not "0": a run that must exercise the device.
inline bool gpu_required() {
    const char* value = std::getenv("RAYFORGE_REQUIRE_GPU");
    return value != nullptr && *value != '\0' && std::strcmp(value, "0") != 0;
}

// "" when device 0 is there, else why not.
inline std::string missing_device() {
    const DeviceListing& listing = device_listing();
    if (!listing.devices.empty()) return "";
    return listing.error.empty() ? std::string("the runtime lists no device") : listing.error;
}

}  // namespace rf::gpu_test

// Statement-like: returns from the test body when there is no device.
#define RF_REQUIRE_DEVICE()                                                                                  \
    do {                                                                                                     \
        const std::string rf_missing_ = ::rf::gpu_test::missing_device();                                    \
        if (!rf_missing_.empty()) {                                                                          \
            if (::rf::gpu_test::gpu_required())                                                              \
                FAIL() << "no CUDA device: " << rf_missing_ << " (RAYFORGE_REQUIRE_GPU is set)";             \
            GTEST_SKIP() << "no CUDA device: " << rf_missing_;                                               \
        }                                                                                                    \
    } while (0)
