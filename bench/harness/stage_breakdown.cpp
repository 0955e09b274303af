#include "stage_breakdown.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <ostream>
#include <sstream>

#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/hlbvh2.h"
#include "core/parallel.h"
#include "device_build_report.h"

namespace rf::bench {
namespace {

template <class Stages, class Build>
Stages median_build(int repetitions, Build&& build, double (*total)(const Stages&)) {
    std::vector<Stages> runs;
    for (int i = 0; i < std::max(1, repetitions); ++i) {
        Stages stages;
        (void)build(stages);
        runs.push_back(stages);
    }
    std::sort(runs.begin(), runs.end(), [&](const Stages& a, const Stages& b) { return total(a) < total(b); });
    return runs[runs.size() / 2];
}

double grid_total(const GridBvhStages& s) { return s.total_ms; }
double hlbvh2_total(const Hlbvh2Stages& s) { return s.total_ms(); }

}  // namespace

std::vector<StageBreakdown> measure_stage_breakdowns(const LoadedScene& scene, int threads, int repetitions) {
    std::vector<StageBreakdown> rows;
    const std::span<const Triangle> triangles = scene.geometry.triangles;
    const BuildOptions options;  // the defaults
    const BvhBuildConfig config = bvh_build_config(options);
    for (const bool split : {false, true}) {
        const GridBvhStages s = median_build<GridBvhStages>(
            repetitions,
            [&](GridBvhStages& stages) {
                return parallel::with_threads(
                    threads, [&] { return build_grid_bvh(triangles, config, options.grid_bvh, split, &stages); });
            },
            grid_total);
        StageBreakdown row;
        row.scene = scene.spec.name;
        row.triangles = triangles.size();
        row.builder = split ? "gridbvh-split" : "gridbvh";
        row.stages = {{"partial tris", s.partial_triangles_ms}, {"sort", s.sort_ms},
                      {"grid0", s.grid0_ms},                    {"coarse levels", s.coarse_levels_ms},
                      {"hierarchy", s.hierarchy_ms},            {"leaves", s.leaf_finish_ms},
                      {"emission", s.emission_ms}};
        row.total_ms = s.total_ms;
        row.detail = std::to_string(s.references) + " refs, " + std::to_string(s.occupied_top_cells) +
                     " top cells, grid " + std::to_string(s.grid_bytes / 1024) + " KiB";
        rows.push_back(row);
    }
    const Hlbvh2Stages h = median_build<Hlbvh2Stages>(
        repetitions,
        [&](Hlbvh2Stages& stages) {
            return parallel::with_threads(threads, [&] { return build_hlbvh2(triangles, config, &stages); });
        },
        hlbvh2_total);
    StageBreakdown row;
    row.scene = scene.spec.name;
    row.triangles = triangles.size();
    row.builder = "hlbvh2";
    row.stages = {{"morton", h.morton_ms}, {"sort", h.sort_ms},  {"clusters", h.clusters_ms},
                  {"bottom", h.bottom_ms}, {"top", h.top_ms},    {"emission", h.emit_ms}};
    row.total_ms = h.total_ms();
    row.detail = std::to_string(h.cluster_count) + " clusters";
    rows.push_back(row);
    return rows;
}

namespace {

// The build with the median device time of `repetitions`, after a warm-up
// (module load, first allocations).
template <class Build>
StageBreakdown median_device_build(const LoadedScene& scene, const std::string& name, int repetitions, Build&& build) {
    (void)build();
    std::vector<DeviceBuildSummary> runs;
    for (int i = 0; i < std::max(1, repetitions); ++i) runs.push_back(build());
    std::sort(runs.begin(), runs.end(), [](const DeviceBuildSummary& a, const DeviceBuildSummary& b) {
        return a.report.device_ms < b.report.device_ms;
    });
    const DeviceBuildSummary& summary = runs[runs.size() / 2];
    const BuildReport& s = summary.report;
    StageBreakdown row;
    row.scene = scene.spec.name;
    row.triangles = scene.geometry.triangles.size();
    row.builder = name;
    row.stages = s.device_stages;
    row.total_ms = s.device_ms;
    std::ostringstream detail;
    detail.setf(std::ios::fixed);
    detail.precision(2);
    detail << "peak " << double(s.peak_device_bytes) / (1024.0 * 1024.0) << " MiB on the device, " << summary.nodes
           << " nodes";
    if (std::isfinite(summary.sah_cost)) detail << ", SAH " << summary.sah_cost;
    detail << (s.detail.empty() ? "" : ", ") << s.detail << "; not in total: upload " << s.upload_ms << ", download "
           << s.download_ms << ", host " << s.host_ms << " ms";
    row.detail = detail.str();
    return row;
}

// An accel built on `device` for `kernel`, summarised by its report.
DeviceBuildSummary device_accel_build(const SceneGeometry& geometry, BuildOptions options, GpuKernel kernel,
                                      int device) {
    options.device = Device{Device::Kind::Cuda, device};
    options.gpu_kernel = kernel;
    const std::unique_ptr<Accel> accel = build_accel(geometry, options);
    const AccelStats stats = accel->stats();
    return {accel->build_report(), stats.node_count, stats.sah_cost};
}

}  // namespace

std::vector<StageBreakdown> measure_device_stage_breakdowns(const LoadedScene& scene, int device, int repetitions) {
    const std::span<const Triangle> triangles = scene.geometry.triangles;
    std::vector<StageBreakdown> rows;
    for (const Builder builder : {Builder::Lbvh30, Builder::Lbvh63, Builder::Hlbvh2, Builder::Ploc, Builder::Hploc,
                                  Builder::GridBvh, Builder::GridBvhSplit}) {
        BuildOptions options;
        options.builder = builder;
        options.device = Device{Device::Kind::Cuda, device};
        rows.push_back(median_device_build(scene, to_string(builder) + " (cuda)", repetitions, [&] {
            DeviceBuildSummary summary;
            const Bvh bvh = build_bvh(triangles, options, &summary.report);
            summary.nodes = bvh.nodes.size();
            summary.sah_cost = bvh.nodes.empty() ? 0.0 : bvh.sah_cost();
            return summary;
        }));
    }
    for (const bool proximity : {false, true}) {
        BuildOptions options;
        options.structure = proximity ? Structure::ProximityGrid : Structure::Grid;
        const GpuKernel kernel = proximity ? GpuKernel::ProximityGrid : GpuKernel::Grid;
        rows.push_back(median_device_build(scene, proximity ? "grid-prox (cuda)" : "grid (cuda)", repetitions,
                                           [&] { return device_accel_build(scene.geometry, options, kernel, device); }));
    }
    // Layout conversions of the default tree (built on the CPU: binned SAH has
    // no device builder), each its own row, the conversion alone its total.
    for (const GpuKernel kernel : {GpuKernel::AilaLaine, GpuKernel::Cwbvh})
        rows.push_back(median_device_build(scene, to_string(kernel) + " layout (cuda)", repetitions, [&] {
            DeviceBuildSummary s = device_accel_build(scene.geometry, BuildOptions{}, kernel, device);
            s.report.device_ms = s.report.layout_ms;
            return s;
        }));
    return rows;
}

void print_stage_breakdowns(std::ostream& out, const std::vector<StageBreakdown>& rows, int threads,
                            int repetitions) {
    if (rows.empty()) return;
    out << "\nBuild stages (dissertation tables 4.1 and 5.1), ms of the median of " << repetitions << " builds, "
        << (threads > 0 ? std::to_string(threads) : std::string("all")) << " threads\n";
    const auto flags = out.flags();
    const auto precision = out.precision();
    out << std::fixed << std::setprecision(1);
    for (const StageBreakdown& row : rows) {
        out << "  " << std::left << std::setw(20) << row.scene << ' ' << std::setw(24) << row.builder << std::right
            << " total " << std::setw(8) << row.total_ms << " |";
        for (const auto& [name, ms] : row.stages) out << ' ' << name << ' ' << ms;
        out << " | " << row.detail << " (" << row.triangles << " triangles)\n";
    }
    out.flags(flags);
    out.precision(precision);
}

}  // namespace rf::bench
