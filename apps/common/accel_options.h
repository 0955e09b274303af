// The acceleration-structure options shared by the commands that build one
// (`render`; `bench` picks structures by name lists instead): --accel,
// --builder, --layout, --optimize and the per-structure parameters.
#pragma once

#include <CLI/CLI.hpp>

#include <string>

#include "rayforge/accel/accel.h"

namespace rf::cli {

struct AccelArgs {
    BuildOptions options;  // defaults: rf::BuildOptions (the fastest correct combination)
    std::string accel, builder, layout, kd_traversal;  // empty = the default
};

void add_accel_options(CLI::App* cmd, AccelArgs& args);
// Parses the names into args.options; throws rf::Error for unknown names.
BuildOptions to_build_options(const AccelArgs& args, int threads);

}  // namespace rf::cli
