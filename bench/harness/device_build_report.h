// A device build in the bench's and the CLI's words: the library's
// BuildReport (rayforge/accel/build_report.h) with the size and quality of
// the tree built, and the one-line form both print.
#pragma once

#include <cstddef>
#include <limits>
#include <string>

#include "rayforge/accel/build_report.h"

namespace rf::bench {

struct DeviceBuildSummary {
    BuildReport report;
    size_t nodes = 0;
    double sah_cost = std::numeric_limits<double>::quiet_NaN();  // NaN for grids
};

// One line: "device build 1.23 ms (bounds 0.01, ...) + layout 0.2 ms; peak
// 12.3 MiB; SAH ...; upload/download/host ms; detail", or "built on the
// host" when the report is not on a device (with the device layout
// conversion's time if any).
std::string format_device_build(const DeviceBuildSummary& build);

}  // namespace rf::bench
