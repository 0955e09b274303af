// The device builders' dispatch: build_bvh_on_device, the device
// counterpart of the CPU's build_bvh_on_cpu (every builder with a device
// version, then treelet restructuring on the device and the host's
// reinsertion optimizer when asked), the seam's
// cuda::build_bvh, and a device build's stages as the public BuildReport.
#include <chrono>

#include "accel/bvh/optimize/reinsertion.h"
#include "backend/backends.h"
#include "core/parallel.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/treelet_restructure.h"
#include "rayforge/core/error.h"

namespace rf::cuda {

bool has_device_builder(Builder builder) {
    switch (builder) {
        case Builder::Lbvh30:
        case Builder::Lbvh63:
        case Builder::Hlbvh2:
        case Builder::Ploc:
        case Builder::Hploc:
        case Builder::GridBvh:
        case Builder::GridBvhSplit: return true;
        default: return false;
    }
}

namespace {

// `resident`: see device_bvh_builders.h (GridBvh always hands its tree back on the host).
Bvh run_device_builder(std::span<const Triangle> triangles, const BuildOptions& options, DeviceBuildStages& s,
                       int device, DeviceBvh* resident) {
    const BvhBuildConfig config = bvh_build_config(options);
    switch (options.builder) {
        case Builder::Lbvh30: return build_lbvh_on_device(triangles, config, 30, &s, device, resident);
        case Builder::Lbvh63: return build_lbvh_on_device(triangles, config, 63, &s, device, resident);
        case Builder::Hlbvh2: return build_hlbvh2_on_device(triangles, config, &s, device, resident);
        case Builder::Ploc: return build_ploc_on_device(triangles, config, options.ploc, &s, device, resident);
        case Builder::Hploc: return build_hploc_on_device(triangles, config, options.ploc, &s, device, resident);
        case Builder::GridBvh: return build_grid_bvh_on_device(triangles, config, options.grid_bvh, false, &s, device);
        case Builder::GridBvhSplit:
            return build_grid_bvh_on_device(triangles, config, options.grid_bvh, true, &s, device);
        default: throw Error("cuda: the " + to_string(options.builder) + " builder has no device version");
    }
}

}  // namespace

Bvh build_bvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, DeviceBuildStages* stages,
                        int device, DeviceBvh* resident) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    const bool optimized = options.treelets.enabled || options.reinsertion.enabled;
    return parallel::with_threads(options.threads, [&] {
        // The optimizers take the tree on the host: the treelet pass
        // uploads it again (a round trip the resident chain does not
        // remove yet), so with either one nothing stays resident.
        Bvh bvh = run_device_builder(triangles, options, s, device, optimized ? nullptr : resident);
        s.on_device = true;
        if (options.treelets.enabled) {
            optimize_treelets_on_device(bvh, triangles, bvh_build_config(options), options.treelets, &s, device);
        }
        if (options.reinsertion.enabled) {
            const auto start = std::chrono::steady_clock::now();
            optimize_reinsertion(bvh, triangles, options.sah, options.reinsertion);
            s.optimize_ms =
                std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
        }
        return bvh;
    });
}

Bvh build_bvh(std::span<const Triangle> triangles, const BuildOptions& options, BuildReport* report) {
    DeviceBuildStages stages;
    Bvh bvh = build_bvh_on_device(triangles, options, &stages, options.device.index);
    if (report) *report = describe_device_build(stages, options.device);
    return bvh;
}

// A stage that did not run is 0 ms (CUDA events never time a launch at
// exactly 0), so the listed stages are the ones that ran.
BuildReport describe_device_build(const DeviceBuildStages& s, const Device& device) {
    BuildReport out;
    out.on_device = s.on_device;
    out.device = device;
    const std::pair<const char*, double> stages[] = {
        {"partial tris", s.partial_triangles_ms}, {"bounds", s.bounds_ms},   {"morton", s.morton_ms},
        {"cell pairs", s.cell_pairs_ms},          {"sort", s.sort_ms},       {"clusters", s.clusters_ms},
        {"grid0", s.grid0_ms},                    {"coarse levels", s.coarse_levels_ms},
        {"inner nodes", s.inner_nodes_ms},        {"bottom", s.bottom_ms},   {"top", s.top_ms},
        {"ploc", s.ploc_ms},                      {"hploc", s.hploc_ms},     {"hierarchy", s.hierarchy_ms},
        {"leaves", s.leaf_finish_ms},             {"cell ranges", s.cell_ranges_ms},
        {"proximity", s.proximity_ms},            {"boxes", s.boxes_ms},     {"emission", s.device_emit_ms},
        {"treelets", s.treelet_ms}};
    for (const auto& [name, ms] : stages)
        if (ms > 0.0) out.device_stages.emplace_back(name, ms);
    out.device_ms = s.device_total_ms();
    out.layout_ms = s.layout_ms;
    out.first_ray_ms = s.first_ray_ms;
    out.upload_ms = s.upload_ms;
    out.download_ms = s.download_ms;
    out.host_ms = s.emit_ms + s.optimize_ms;
    out.peak_device_bytes = s.peak_device_bytes;
    const auto add = [&](const std::string& text) { out.detail += (out.detail.empty() ? "" : ", ") + text; };
    if (s.build_span_ms > 0.0) add("one event pair around the build: " + std::to_string(s.build_span_ms) + " ms");
    if (s.cluster_count) add(std::to_string(s.cluster_count) + " clusters");
    if (s.bottom_levels) add(std::to_string(s.bottom_levels) + " bottom levels");
    if (s.top_levels) add(std::to_string(s.top_levels) + " top levels");
    if (s.ploc_iterations) add(std::to_string(s.ploc_iterations) + " iterations");
    if (s.references) add(std::to_string(s.references) + " references");
    if (s.occupied_top_cells) add(std::to_string(s.occupied_top_cells) + " top cells");
    return out;
}

}  // namespace rf::cuda
