// The acceleration-structure options shared by the commands that build one
// (`render`; `bench` picks structures by name lists instead): --accel,
// --builder, --layout, --optimize and the per-structure parameters.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"

namespace rf::cli {

struct AccelArgs {
    BuildOptions options;  // defaults: rf::BuildOptions (the fastest correct combination)
    std::string accel, builder, layout, kd_traversal;  // empty = the default
    // Animated scenes: how the structure follows the motion (--update ...).
    UpdateOptions update;
    std::string update_method, adapt_reading, cluster_heuristic, cluster_generation;  // empty = the default
    float adapt_dm = 0.0f, adapt_de = 0.0f;  // 0 = the reading's value
};

void add_accel_options(CLI::App* cmd, AccelArgs& args);
// --update and its parameters (render, view).
void add_update_options(CLI::App* cmd, AccelArgs& args);
// Parses the names into args.options; throws rf::Error for unknown names.
BuildOptions to_build_options(const AccelArgs& args, int threads);
// The update options (--update and the adapt/cluster parameters); `scene_default`
// is the scene file's update method when it names one (a CPU-only one
// becomes rebuild, with a note, on a CUDA `device`, where a CPU-only
// --update is an error). Throws rf::Error for unknown names.
UpdateOptions to_update_options(const AccelArgs& args, const std::string& scene_default = "",
                                const Device& device = {});
// The update method used when neither the command line nor the scene names one.
inline constexpr UpdateMethod kDefaultUpdateMethod = UpdateMethod::Rebuild;  // measured: docs/benchmarks.md

}  // namespace rf::cli
