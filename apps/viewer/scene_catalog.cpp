#include "scene_catalog.h"

#include "bench_scenes.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf::viewer {

SceneCatalog SceneCatalog::discover(const std::string& explicit_dir) {
    SceneCatalog catalog;
    catalog.scenes_dir = bench::find_scenes_dir(explicit_dir);  // an explicit folder without views.json throws
    try {
        catalog.shared_names = bench::views_json_scene_names(catalog.scenes_dir);
    } catch (const Error& e) {  // a broken views.json costs the switcher, not the viewer
        catalog.problem = e.what();
    }
    for (const std::string& name : builtin_scene_names()) catalog.builtin_names.push_back("builtin:" + name);
    return catalog;
}

SceneSource SceneCatalog::resolve(const std::string& name_or_path) const {
    const bench::SceneSpec spec = bench::resolve_scene(name_or_path, scenes_dir);
    SceneSource source;
    source.name = spec.name;
    source.path = spec.path;
    source.views = spec.views;
    if (spec.has_light) source.light = spec.light;
    return source;
}

}  // namespace rf::viewer
