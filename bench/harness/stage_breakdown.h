// Build-stage breakdowns of the dissertation's GPU builders run on the CPU:
// GridBvh / GridBvhSplit (its table 4.1) and HLBVH2 (its table 5.1), and of
// the builders that run on a CUDA device (--device cuda). Printed by the
// garanzha2014 preset after its main tables.
#pragma once

#include <iosfwd>
#include <string>
#include <utility>
#include <vector>

#include "bench_scenes.h"

namespace rf::bench {

struct StageBreakdown {
    std::string scene;
    size_t triangles = 0;
    std::string builder;                                // "gridbvh", "gridbvh-split", "hlbvh2", "lbvh30 (cuda)"
    std::vector<std::pair<std::string, double>> stages; // stage name -> ms (of the median build)
    double total_ms = 0.0;
    std::string detail;                                 // sizes: references, clusters, ...
};

// Builds each of the three builders `repetitions` times over `scene` with
// `threads` threads (0 = all cores) and keeps the build with the median total.
std::vector<StageBreakdown> measure_stage_breakdowns(const LoadedScene& scene, int threads, int repetitions);

// The device builders (lbvh30, lbvh63, hlbvh2, ploc, gridbvh,
// gridbvh-split, the uniform grid with and without proximity clouds) and the
// device layout conversions of the default BVH (aila-laine, cwbvh) on CUDA
// device `device`, each the build with the median device time of
// `repetitions`.
// Throws rf::Error when the backend or the device is missing.
std::vector<StageBreakdown> measure_device_stage_breakdowns(const LoadedScene& scene, int device, int repetitions);

void print_stage_breakdowns(std::ostream& out, const std::vector<StageBreakdown>& rows, int threads,
                            int repetitions);

}  // namespace rf::bench
