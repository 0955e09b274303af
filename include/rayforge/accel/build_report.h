// How an acceleration structure was built: where, the stages and their
// times, the transfers, the peak device memory and the builder's sizes.
// A CPU build reports no stages; a device build (BuildOptions::device on a
// CUDA device with a device builder) every stage that ran there.
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "rayforge/backend/device.h"

namespace rf {

struct BuildReport {
    bool on_device = false;                                     // false: built on the host
    Device device;                                              // where the structure lives
    std::vector<std::pair<std::string, double>> device_stages;  // name -> ms, the device stages that ran, in order
    double device_ms = 0.0;                                     // their sum (the layout conversion excluded)
    double layout_ms = 0.0;                                     // layout conversion on the device, 0 when none
    double first_ray_ms = 0.0;  // a tracer's device build: triangles on the device to the first ray possible
    double upload_ms = 0.0, download_ms = 0.0;                  // transfers
    double host_ms = 0.0;                                       // host parts of a device build: emission, optimizer
    size_t peak_device_bytes = 0;                               // sum of the live device buffers at the peak
    std::string detail;  // builder-specific sizes: clusters, levels, iterations, references
};

}  // namespace rf
