// `rayforge view`: the interactive viewer's entry point. The window, its
// panel and its input live in the viewer's GUI part (built when GLFW 3.3 and
// Dear ImGui are found); without them run_viewer says so in one error.
#pragma once

#include <functional>
#include <string>

#include <optional>

#include "script.h"
#include "session.h"
#include "view_settings.h"

namespace rf::viewer {

struct ViewerConfig {
    std::string scene;           // a file, builtin:NAME or a views.json name
    std::string scenes_dir;      // --scenes-dir ("" = search for ../shared/scenes)
    ViewSettings settings;       // from the render options on the command line
    // Lights, the start camera and the first scene's settings (SessionConfig::prepare).
    PrepareScene prepare;
    LoadOptions first_load;      // how the first scene loads (--animation)
    std::optional<Script> script;  // --script FILE, parsed: run it, then exit with its verdict
    std::string bookmarks = "rayforge-bookmarks.json";
    int window_width = 0, window_height = 0;  // 0 = the image size
    double script_timeout_s = 120.0;          // the longest any script wait may take
    Clock::time_point launched = Clock::now();
};

// Runs the viewer until its window closes (or the script ends): 0 on
// success, 1 when a script command failed. Throws rf::Error when it cannot
// start (no display, no OpenGL 3.3, a build without
// the viewer).
int run_viewer(const ViewerConfig& config);

// Whether this rayforge was built with the viewer's window (GLFW, ImGui).
bool viewer_built();

}  // namespace rf::viewer
