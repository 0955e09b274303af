// Where a command runs: the --device and --gpu-kernel options shared by
// `render`, `view`, `build` and `bench` (names: rayforge/backend/device.h).
// Bad names are usage errors in every build; asking for CUDA in a build
// without the backend is the library's one-line error.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/backend/device.h"

namespace rf::cli {

// Validators for one name (with ->delimiter(','), for each item of a list);
// `allow_all` also accepts "all".
CLI::Validator device_validator();
CLI::Validator gpu_kernel_validator(bool allow_all = false);

// --device bound to `device`.
CLI::Option* add_device_option(CLI::App* cmd, Device& device, const std::string& help);
// --gpu-kernel bound to build.gpu_kernel.
CLI::Option* add_gpu_kernel_option(CLI::App* cmd, BuildOptions& build);

// --build-on device|host: where a CUDA run builds its structure (default
// device: the device builders and layout conversions, where the builder has
// one). Bound to BuildOptions::build_on_device; check_build_on says it
// needs a CUDA device.
CLI::Option* add_build_on_option(CLI::App* cmd, bool& build_on_device);
void check_build_on(const CLI::App* cmd, const Device& device);

// Throws rf::Error "--device NAME: <why>" when `device` is a CUDA device
// this process cannot use (backend not built, no driver, no such device).
void require_usable(const Device& device);

}  // namespace rf::cli
