// Placeholder: the HLBVH2 builder is not implemented yet.
#include "accel/bvh/build/hlbvh2.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_hlbvh2(std::span<const Triangle> triangles, const BuildOptions& options) {
    throw Error("the HLBVH2 builder is not implemented yet");
}

}  // namespace rf
