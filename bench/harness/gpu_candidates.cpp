#include "gpu_candidates.h"

#include <algorithm>

#include "rayforge/core/error.h"

namespace rf::bench {
namespace {

// The builder a kernel's structure gets when no candidate names one.
std::string default_builder(const std::string& structure) {
    if (structure == "bvh") return to_string(BuildOptions{}.builder);
    if (structure == "kdtree") return "sah";
    return "uniform-auto";  // grid, grid-proximity: Zlatuška 2009's resolution rule
}

}  // namespace

std::string gpu_kernel_structure(GpuKernel kernel) {
    switch (kernel) {
        case GpuKernel::Bvh2:
        case GpuKernel::AilaLaine:
        case GpuKernel::AilaLaineFma:
        case GpuKernel::Cwbvh:
        case GpuKernel::CwbvhFma: return "bvh";
        case GpuKernel::KdShortStack:
        case GpuKernel::KdRestart: return "kdtree";
        case GpuKernel::Grid: return "grid";
        case GpuKernel::ProximityGrid: return "grid-proximity";
    }
    return "?";
}

std::vector<GpuCandidate> gpu_candidates(const std::vector<GpuKernel>& kernels,
                                         const std::vector<Candidate>& candidates) {
    std::vector<GpuCandidate> rows;
    for (GpuKernel kernel : kernels) {
        const std::string structure = gpu_kernel_structure(kernel);
        std::vector<Candidate> builds;
        for (const Candidate& c : candidates) {
            if (c.structure != structure) continue;
            const bool seen = std::any_of(builds.begin(), builds.end(),
                                          [&](const Candidate& b) { return b.builder == c.builder; });
            if (!seen) builds.push_back(c);
        }
        if (builds.empty()) {
            const std::string builder = default_builder(structure);
            for (const Candidate& c : candidate_catalogue()) {
                if (c.structure == structure && c.builder == builder && c.implemented) {
                    builds.push_back(c);
                    break;
                }
            }
            if (builds.empty()) throw Error("bench: no " + structure + " build for GPU kernel " + to_string(kernel));
        }
        for (Candidate& build : builds) {
            build.layout = to_string(kernel);
            build.source = "GPU kernel " + to_string(kernel);
            rows.push_back({kernel, build});
        }
    }
    return rows;
}

}  // namespace rf::bench
