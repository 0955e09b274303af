// Placeholder: the sweep SAH builder is not implemented yet.
#include "accel/bvh/build/sweep_sah.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_sweep_sah(std::span<const Triangle> triangles, const BuildOptions& options) {
    throw Error("the sweep SAH builder is not implemented yet");
}

}  // namespace rf
