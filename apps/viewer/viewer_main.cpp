// run_viewer with the window: the window, then the loop. (The script was
// parsed by the caller, so a typo fails before a window opens.)
#include <algorithm>

#include "viewer.h"
#include "viewer_app.h"

namespace rf::viewer {

bool viewer_built() { return true; }

int run_viewer(const ViewerConfig& config) {
    int width = config.window_width, height = config.window_height;
    if (width <= 0 || height <= 0) {
        // The image's size, enlarged by a whole factor while it is small, so the panel fits beside the picture.
        const RenderOptions film = film_options(config.settings, false, 1);
        const int factor = std::max(1, std::min(800 / std::max(film.width, 1), 600 / std::max(film.height, 1)));
        width = std::min(film.width * factor, 1600);
        height = std::min(film.height * factor, 1000);
    }
    GlWindow window(width, height, "rayforge view");
    App app(config, window);
    return app.run();
}

}  // namespace rf::viewer
