// Placeholder: the GridBvh builder is not implemented yet.
#include "accel/bvh/build/grid_bvh.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_grid_bvh(std::span<const Triangle> triangles, const BuildOptions& options, bool partial_triangles) {
    throw Error("the GridBvh builder is not implemented yet");
}

}  // namespace rf
