// Placeholder: the reinsertion optimizer is not implemented yet.
#include "accel/bvh/optimize/reinsertion.h"

#include "rayforge/core/error.h"

namespace rf {

void optimize_reinsertion(Bvh& bvh, std::span<const Triangle> triangles, const BuildOptions& options) {
    throw Error("the reinsertion optimizer is not implemented yet");
}

}  // namespace rf
