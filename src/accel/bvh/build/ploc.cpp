// Placeholder: the PLOC builder is not implemented yet.
#include "accel/bvh/build/ploc.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_ploc(std::span<const Triangle> triangles, const BuildOptions& options) {
    throw Error("the PLOC builder is not implemented yet");
}

}  // namespace rf
