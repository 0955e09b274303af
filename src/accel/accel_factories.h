// Constructors of each structure's rf::Accel, one per structure family;
// build_accel (accel.cpp) validates the options and dispatches here.
#pragma once

#include <memory>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf {

// Uniform grid, plain (3D-DDA) or with proximity clouds (options.structure
// says which). Defined in accel/grid/grid_accel.cpp.
std::unique_ptr<Accel> make_grid_accel(const SceneGeometry& geometry, const BuildOptions& options);

// SAH kd-tree with the traversal named in options.kdtree.traversal. Defined in
// accel/kdtree/kdtree_accel.cpp.
std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry& geometry, const BuildOptions& options);

// A built canonical BVH traced in options.layout (Bvh4 or Bvh8): collapses
// `bvh` and wraps the result. `build_ms` is the time spent building `bvh`;
// the collapse is timed here and reported as layout_ms (and added to build_ms).
// `name` is the stats name, e.g. "bvh/sbvh/bvh8". Defined in accel/bvh/layout/wide_bvh_accel.cpp.
std::unique_ptr<Accel> make_wide_bvh_accel(const SceneGeometry& geometry, Bvh bvh, const BuildOptions& options,
                                           double build_ms, std::string name);

}  // namespace rf
