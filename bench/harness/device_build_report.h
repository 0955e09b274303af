// What one device build did, in the bench's and the CLI's words: the stages
// of rf::cuda::DeviceBuildStages that ran, in pipeline order, the transfers,
// the host's part and the builder's sizes. CUDA-free (DeviceBuildStages is
// a plain struct), so it compiles with or without the backend.
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "rayforge/backend/cuda_build.h"

namespace rf::bench {

struct GpuBuildStages {
    bool on_device = false;                                     // false: built on the host, nothing below
    std::vector<std::pair<std::string, double>> device_stages;  // name -> ms, the stages that ran
    double device_ms = 0.0;                                     // their sum (layout conversion excluded)
    double layout_ms = 0.0;                                     // device layout conversion, 0 when none
    double upload_ms = 0.0, download_ms = 0.0, host_ms = 0.0;   // host: emission, optimizer
    size_t peak_device_bytes = 0;
    size_t nodes = 0;
    double sah_cost = 0.0;                                      // NaN for grids
    std::string detail;  // builder-specific sizes (clusters, levels, references)
};

// A stage that did not run is 0 ms (CUDA events never time a launch at
// exactly 0), so the listed stages are the ones that ran.
GpuBuildStages describe_device_build(const cuda::DeviceBuildStages& stages, size_t nodes, double sah_cost);

// One line: "device build 1.23 ms (bounds 0.01, ...) + layout 0.2 ms; peak
// 12.3 MiB; SAH ...; upload/download/host ms; detail", or "built on the
// host" when !on_device (with the device layout conversion's time if any).
std::string format_device_build(const GpuBuildStages& build);

}  // namespace rf::bench
