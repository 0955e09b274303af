// rf::cuda::build_bvh_on_device: the device counterpart of rf::build_bvh,
// dispatching options.builder to its device builder (issue 7) and running
// the host's reinsertion optimizer afterwards when asked, as build_bvh does.
#include <chrono>

#include "accel/bvh/optimize/reinsertion.h"
#include "backend/cpu/parallel.h"
#include "backend/cuda/device_bvh_builders.h"
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

namespace {

Bvh run_device_builder(std::span<const Triangle> triangles, const BuildOptions& options, DeviceBuildStages& s,
                       int device) {
    const BvhBuildConfig config = bvh_build_config(options);
    switch (options.builder) {
        case Builder::Lbvh30: return build_lbvh_on_device(triangles, config, 30, &s, device);
        case Builder::Lbvh63: return build_lbvh_on_device(triangles, config, 63, &s, device);
        case Builder::Hlbvh2: return build_hlbvh2_on_device(triangles, config, &s, device);
        case Builder::Ploc: return build_ploc_on_device(triangles, config, options.ploc, &s, device);
        case Builder::GridBvh: return build_grid_bvh_on_device(triangles, config, options.grid_bvh, false, &s, device);
        case Builder::GridBvhSplit:
            return build_grid_bvh_on_device(triangles, config, options.grid_bvh, true, &s, device);
        default: throw Error("cuda: the " + to_string(options.builder) + " builder has no device version");
    }
}

}  // namespace

Bvh build_bvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, DeviceBuildStages* stages,
                        int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    return parallel::with_threads(options.threads, [&] {
        Bvh bvh = run_device_builder(triangles, options, s, device);
        s.on_device = true;
        if (options.reinsertion.enabled) {
            const auto start = std::chrono::steady_clock::now();
            optimize_reinsertion(bvh, triangles, options.sah, options.reinsertion);
            s.optimize_ms =
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        }
        return bvh;
    });
}

}  // namespace rf::cuda
