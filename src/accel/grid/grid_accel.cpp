// Placeholder: uniform grids are not implemented yet.
#include "accel/accel_factories.h"
#include "rayforge/core/error.h"

namespace rf {

std::unique_ptr<Accel> make_grid_accel(const SceneGeometry&, const BuildOptions&) {
    throw Error("the uniform grid is not implemented yet");
}

}  // namespace rf
