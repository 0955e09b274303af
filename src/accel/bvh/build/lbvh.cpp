// Placeholder: the LBVH builder is not implemented yet.
#include "accel/bvh/build/lbvh.h"

#include "rayforge/core/error.h"

namespace rf {

Bvh build_lbvh(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits) {
    throw Error("the LBVH builder is not implemented yet");
}

}  // namespace rf
