// The acceleration-structure options shared by the commands that build one
// (`render`, `view`, `build`; `bench` picks structures by name lists
// instead): --accel, --builder, --layout, --optimize and the per-structure
// parameters, bound to a BuildOptions; --update and its parameters, bound
// to an UpdateOptions.
#pragma once

#include <CLI/CLI.hpp>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"

namespace rf::cli {

void add_accel_options(CLI::App* cmd, BuildOptions& build);
// --update and its parameters (render, view). Without --update the world
// takes the scene file's method, else rf::kDefaultUpdateMethod.
void add_update_options(CLI::App* cmd, UpdateOptions& update);

}  // namespace rf::cli
