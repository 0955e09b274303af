// Placeholder: the kd-tree is not implemented yet.
#include "accel/accel_factories.h"
#include "rayforge/core/error.h"

namespace rf {

std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry&, const BuildOptions&) {
    throw Error("the kd-tree is not implemented yet");
}

}  // namespace rf
