// rf::cuda::build_bvh_on_device: the device counterpart of rf::build_bvh,
// dispatching options.builder to its device builder (issue 7) and running
// the host's reinsertion optimizer afterwards when asked, as build_bvh does.
#include <chrono>

#include "accel/bvh/optimize/reinsertion.h"
#include "rayforge/backend/cuda_build.h"
#include "rayforge/core/error.h"

namespace rf::cuda {

bool has_device_builder(Builder builder) {
    switch (builder) {
        case Builder::Lbvh30:
        case Builder::Lbvh63:
        case Builder::Hlbvh2:
        case Builder::Ploc:
        case Builder::GridBvh:
        case Builder::GridBvhSplit: return true;
        default: return false;
    }
}

Bvh build_bvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, DeviceBuildStages* stages,
                        int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    Bvh bvh;
    switch (options.builder) {
        case Builder::Lbvh30: bvh = build_lbvh_on_device(triangles, options, 30, &s, device); break;
        case Builder::Lbvh63: bvh = build_lbvh_on_device(triangles, options, 63, &s, device); break;
        case Builder::Hlbvh2: bvh = build_hlbvh2_on_device(triangles, options, &s, device); break;
        case Builder::Ploc: bvh = build_ploc_on_device(triangles, options, &s, device); break;
        case Builder::GridBvh: bvh = build_grid_bvh_on_device(triangles, options, false, &s, device); break;
        case Builder::GridBvhSplit: bvh = build_grid_bvh_on_device(triangles, options, true, &s, device); break;
        default: throw Error("cuda: the " + to_string(options.builder) + " builder has no device version");
    }
    s.on_device = true;
    if (options.optimize) {
        const auto start = std::chrono::steady_clock::now();
        optimize_reinsertion(bvh, triangles, options);
        s.optimize_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    }
    return bvh;
}

}  // namespace rf::cuda
