// Placeholder: the SBVH builder is not implemented yet.
#include "accel/bvh/build/sbvh.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_sbvh(std::span<const Triangle> triangles, const BuildOptions& options) {
    throw Error("the SBVH builder is not implemented yet");
}

}  // namespace rf
