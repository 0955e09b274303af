// Where a command runs: the --device and --gpu-kernel options shared by
// `render`, `build` and `bench` (names: rayforge/backend/device.h). Bad names
// are usage errors in every build; asking for CUDA in a build without the
// backend is the library's one-line error.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "rayforge/backend/device.h"

namespace rf::cli {

// Validators for one name (with ->delimiter(','), for each item of a list);
// `allow_all` also accepts "all".
CLI::Validator device_validator();
CLI::Validator gpu_kernel_validator(bool allow_all = false);

// --build-on device|host: where a CUDA run builds its structure (default
// device: the device builders and layout conversions of issue 7, where the
// builder has one). Returns BuildOptions::build_on_device; throws rf::Error
// when the option is given without a CUDA device.
void add_build_on_option(CLI::App* cmd, std::string& value);
bool parse_build_on(const std::string& value, bool cuda_device);

// Throws rf::Error "OPTION: <why>" when `device` is a CUDA device this
// process cannot use (backend not built, no driver, no such device).
void require_usable(const Device& device, const std::string& option);

}  // namespace rf::cli
