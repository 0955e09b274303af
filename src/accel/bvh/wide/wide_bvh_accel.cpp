// Placeholder: wide BVH layouts are not implemented yet.
#include "accel/accel_factories.h"
#include "rayforge/core/error.h"

namespace rf {

std::unique_ptr<Accel> make_wide_bvh_accel(const SceneGeometry&, Bvh, const BuildOptions&, double, std::string) {
    throw Error("the bvh4/bvh8 layouts are not implemented yet");
}

}  // namespace rf
