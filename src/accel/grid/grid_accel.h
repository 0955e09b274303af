// rf::Accel over a uniform grid, plain or with proximity clouds (Amanatides
// and Woo 1987; Bogolepov et al.'s proximity clouds), traversed by
// trace/grid_traversal.h (accel/view_accel.h with the GridTracer).
#pragma once

#include "accel/grid/uniform_grid.h"
#include "accel/view_accel.h"

namespace rf {

void describe_structure(const UniformGrid& grid, AccelStats& stats);

using GridAccel = ViewAccel<UniformGrid, GridTracer>;

}  // namespace rf
