// `rayforge build`: builds a scene's acceleration structure several times
// and reports each build: on the CPU the wall time, SAH cost, nodes
// and memory; on a CUDA device (--device cuda) the time of every device
// stage, the transfers and the host's part, the peak device memory, the SAH
// cost and the node count, and with --convert the device layout conversion.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "elapsed.h"
#include "device_build_report.h"
#include "rayforge/accel/accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cli {
namespace {

using Clock = std::chrono::steady_clock;

double median(std::vector<double> values) {
    std::sort(values.begin(), values.end());
    const size_t n = values.size();
    return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// The device build of `options` (a BVH builder's canonical tree; another
// structure as build_accel makes it for the device: uniform grids on the
// device, a kd-tree on the host, uploaded), and, with `convert`, the layout
// conversion of the BVH on the device.
bench::DeviceBuildSummary device_build(const SceneGeometry& geometry, BuildOptions options,
                                       const std::string& convert) {
    const bool grid = options.structure == Structure::Grid || options.structure == Structure::ProximityGrid;
    if (options.structure != Structure::Bvh || !convert.empty()) {
        if (!convert.empty()) options.gpu_kernel = parse_gpu_kernel(convert);
        const std::unique_ptr<Accel> accel = build_accel(geometry, options);
        const AccelStats stats = accel->stats();
        bench::DeviceBuildSummary summary{accel->build_report(), stats.node_count, stats.sah_cost};
        if (grid)
            summary.report.detail += (summary.report.detail.empty() ? "" : ", ") + std::to_string(stats.leaf_count) +
                                     " non-empty cells";
        return summary;
    }
    bench::DeviceBuildSummary summary;
    const Bvh bvh = build_bvh(geometry.triangles, options, &summary.report);
    summary.nodes = bvh.nodes.size();
    summary.sah_cost = bvh.nodes.empty() ? 0.0 : bvh.sah_cost();
    return summary;
}

}  // namespace

CLI::App* add_build_command(CLI::App& app, BuildArgs& a) {
    CLI::App* cmd = app.add_subcommand(
        "build", "Build a scene's acceleration structure and report the build: time per stage on a CUDA device, "
                 "memory, SAH cost and nodes");
    cmd->add_option("scene", a.scene, "Scene file (.obj, .gltf, .glb, .ply, .aff, .json) or builtin:NAME")->required();
    add_accel_options(cmd, a.build);
    add_device_option(cmd, a.build.device, "Where to build: cpu (default), cuda (= cuda:0) or cuda:N");
    cmd->add_option("--reps", a.repetitions, "Builds, after one warm-up build (default 3)")
        ->check(CLI::Range(1, 1000));
    cmd->add_option("--threads", a.build.threads, "CPU threads (0 = all cores)")->check(CLI::NonNegativeNumber);
    cmd->add_option("--convert", a.convert,
                    "With --device cuda and a BVH: also convert it on the device to a GPU layout, aila-laine or "
                    "cwbvh, timed separately")
        ->check(CLI::IsMember({"aila-laine", "cwbvh"}));
    return cmd;
}

int run_build(const BuildArgs& a) {
    const Device device = a.build.device;
    require_usable(device);
    if (!a.convert.empty() && !device.is_cuda()) throw Error("--convert: needs --device cuda");
    if (!a.convert.empty() && a.build.structure != Structure::Bvh) throw Error("--convert: needs --accel bvh");
    const BuildOptions& options = a.build;  // build_accel and build_bvh check them (and match kernel and structure)

    const Clock::time_point load_start = Clock::now();
    const SceneGeometry geometry = SceneGeometry::build(load_scene(a.scene));
    std::printf("%s: %zu triangles, loaded in %.1f ms\n", a.scene.c_str(), geometry.size(), ms_since(load_start));
    const std::string what = to_string(options.structure) +
                             (options.structure == Structure::Bvh ? "/" + to_string(options.builder) : std::string());

    std::vector<double> totals;
    if (device.is_cuda()) {
        (void)device_build(geometry, options, a.convert);  // warm-up: module load, first allocations
        for (int r = 0; r < a.repetitions; ++r) {
            const bench::DeviceBuildSummary build = device_build(geometry, options, a.convert);
            std::printf("%s on %s, build %d: %s\n", what.c_str(), to_string(device).c_str(), r + 1,
                        bench::format_device_build(build).c_str());
            totals.push_back(build.report.device_ms);
        }
        std::printf("%s on %s: median device time %.3f ms of %d builds\n", what.c_str(), to_string(device).c_str(),
                    median(totals), a.repetitions);
        return 0;
    }
    (void)build_accel(geometry, options);  // warm-up: thread pool, first page faults
    for (int r = 0; r < a.repetitions; ++r) {
        const Clock::time_point start = Clock::now();
        const std::unique_ptr<Accel> accel = build_accel(geometry, options);
        const double wall_ms = ms_since(start);
        const AccelStats stats = accel->stats();
        char quality[64] = "";
        if (std::isfinite(stats.sah_cost)) std::snprintf(quality, sizeof(quality), "SAH %.2f, ", stats.sah_cost);
        std::printf("%s on cpu, build %d: %.2f ms (%s, layout %.2f ms); %s%zu nodes, %zu leaves, %.2f MB\n",
                    what.c_str(), r + 1, wall_ms, stats.name.c_str(), stats.layout_ms, quality,
                    stats.node_count, stats.leaf_count, double(stats.bytes) / 1e6);
        totals.push_back(wall_ms);
    }
    std::printf("%s on cpu: median %.2f ms of %d builds\n", what.c_str(), median(totals), a.repetitions);
    return 0;
}

}  // namespace rf::cli
