// run_viewer in a build without GLFW 3.3 or Dear ImGui: one clear error.
#include "rayforge/core/error.h"
#include "viewer.h"

namespace rf::viewer {

bool viewer_built() { return false; }

int run_viewer(const ViewerConfig&) {
    throw Error("this rayforge was built without the viewer (GLFW 3.3 and Dear ImGui were not found at configure "
                "time; scripts/setup-deps.sh installs libglfw3-dev and libimgui-dev)");
}

}  // namespace rf::viewer
