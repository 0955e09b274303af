// The scenes the viewer offers: the scenes of ../shared/scenes/views.json
// (with their benchmark views and point light) when that folder is found,
// and the built-in scenes. Any file the CLI loads works too, by path.
#pragma once

#include <string>
#include <vector>

#include "session.h"

namespace rf::viewer {

struct SceneCatalog {
    std::string scenes_dir;                 // "" when no views.json was found
    std::vector<std::string> shared_names;  // views.json names, in file order
    std::vector<std::string> builtin_names; // "builtin:cornell", ...
    std::string problem;                    // why views.json could not be read, if it could not

    // `explicit_dir`: --scenes-dir ("" = search as the bench does).
    static SceneCatalog discover(const std::string& explicit_dir);
    // A views.json name, a file or builtin:NAME; throws rf::Error when it is
    // none of them (the message lists the known names).
    [[nodiscard]] SceneSource resolve(const std::string& name_or_path) const;
};

}  // namespace rf::viewer
