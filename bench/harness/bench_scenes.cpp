#include "bench_scenes.h"

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf::bench {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr const char* kViewsFile = "views.json";
constexpr const char* kBuiltinPrefix = "builtin:";

bool has_views(const fs::path& dir) {
    std::error_code ec;
    return fs::is_regular_file(dir / kViewsFile, ec);
}

// shared/scenes in `start` or one of its ancestors (also as a sibling "shared").
std::string search_upwards(fs::path start) {
    std::error_code ec;
    for (int depth = 0; depth < 6 && !start.empty(); ++depth) {
        if (has_views(start / "shared" / "scenes")) return (start / "shared" / "scenes").string();
        if (has_views(start / ".." / "shared" / "scenes"))
            return fs::weakly_canonical(start / ".." / "shared" / "scenes", ec).string();
        if (start == start.parent_path()) break;
        start = start.parent_path();
    }
    return "";
}

Json read_views(const std::string& scenes_dir) {
    const fs::path file = fs::path(scenes_dir) / kViewsFile;
    std::ifstream in(file);
    if (!in) throw Error(file.string() + ": cannot open");
    try {
        return Json::parse(in);
    } catch (const Json::exception& e) {
        throw Error(file.string() + ": invalid JSON (" + std::string(e.what()) + ")");
    }
}

Vec3f read_vec3(const Json& value, const std::string& where) {
    if (!value.is_array() || value.size() != 3) throw Error(where + ": expected [x, y, z]");
    Vec3f v;
    for (int i = 0; i < 3; ++i) {
        if (!value[size_t(i)].is_number()) throw Error(where + ": expected numbers");
        const float f = value[size_t(i)].get<float>();
        if (!std::isfinite(f)) throw Error(where + ": not a finite number");
        (&v.x)[i] = f;
    }
    return v;
}

float diagonal(const LoadedScene& scene) { return length(scene.geometry.bounds.extent()); }

}  // namespace

std::string find_scenes_dir(const std::string& explicit_dir) {
    if (!explicit_dir.empty()) {
        if (!has_views(explicit_dir)) throw Error("--scenes-dir " + explicit_dir + ": no views.json there");
        return explicit_dir;
    }
    if (const char* env = std::getenv("RAYFORGE_SCENES_DIR"); env && *env) {
        if (!has_views(env)) throw Error("RAYFORGE_SCENES_DIR=" + std::string(env) + ": no views.json there");
        return env;
    }
    std::error_code ec;
    std::string found = search_upwards(fs::current_path(ec));
    if (found.empty()) found = search_upwards(fs::read_symlink("/proc/self/exe", ec).parent_path());
    return found;
}

std::vector<std::string> views_json_scene_names(const std::string& scenes_dir) {
    std::vector<std::string> names;
    if (scenes_dir.empty()) return names;
    const Json views = read_views(scenes_dir);
    if (views.contains("scenes") && views["scenes"].is_object())
        for (const auto& [name, _] : views["scenes"].items()) names.push_back(name);
    return names;
}

SceneSpec resolve_scene(const std::string& name, const std::string& scenes_dir) {
    SceneSpec spec;
    if (name.rfind(kBuiltinPrefix, 0) == 0) {
        spec.name = name;
        spec.path = name;
        return spec;
    }
    std::error_code ec;
    if (fs::is_regular_file(name, ec)) {
        spec.name = fs::path(name).stem().string();
        spec.path = name;
        return spec;
    }
    if (scenes_dir.empty()) {
        throw Error("scene '" + name + "' is neither a file nor builtin:NAME, and no views.json was found " +
                    "(give --scenes-dir or set RAYFORGE_SCENES_DIR)");
    }
    const Json views = read_views(scenes_dir);
    const std::string where = std::string(kViewsFile) + " scene '" + name + "'";
    if (!views.contains("scenes") || !views["scenes"].contains(name)) {
        std::string known;
        for (const std::string& n : views_json_scene_names(scenes_dir)) known += (known.empty() ? "" : ", ") + n;
        throw Error("unknown scene '" + name + "' (views.json has: " + known + "; or give a file or builtin:NAME)");
    }
    const Json& entry = views["scenes"][name];
    if (!entry.contains("file") || !entry["file"].is_string()) throw Error(where + ": no \"file\"");
    spec.name = name;
    spec.path = (fs::path(scenes_dir) / entry["file"].get<std::string>()).string();
    if (entry.contains("views") && entry["views"].is_array()) {
        for (const Json& v : entry["views"]) {
            Camera camera;
            camera.eye = read_vec3(v.at("eye"), where + " view eye");
            camera.target = read_vec3(v.at("target"), where + " view target");
            if (v.contains("up")) camera.up = read_vec3(v["up"], where + " view up");
            if (v.contains("fov")) camera.vfov_degrees = v["fov"].get<float>();
            spec.views.push_back(camera);
        }
    }
    if (entry.contains("light")) {
        spec.light = read_vec3(entry["light"], where + " light");
        spec.has_light = true;
    }
    if (entry.contains("ao_radius")) {
        spec.ao_radius = entry["ao_radius"].get<float>();
        if (!(spec.ao_radius > 0.0f) || !std::isfinite(spec.ao_radius))
            throw Error(where + ": ao_radius must be a positive number");
    }
    return spec;
}

std::vector<std::string> default_scene_names(const std::string& scenes_dir) {
    if (!scenes_dir.empty()) return {"sponza", "conference", "bunny"};
    return {"builtin:sphereflake", "builtin:terrain", "builtin:instances"};
}

LoadedScene load_bench_scene(const SceneSpec& spec) {
    LoadedScene loaded;
    loaded.spec = spec;
    const auto start = std::chrono::steady_clock::now();
    LoadOptions options;
    options.load_textures = false;  // the bench traces geometry only
    loaded.scene = load_scene(spec.path, options);
    loaded.geometry = SceneGeometry::build(loaded.scene);
    loaded.load_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (loaded.geometry.triangles.empty()) throw Error(spec.path + ": the scene has no triangles");
    return loaded;
}

int view_count(const LoadedScene& scene) { return std::max<int>(1, int(scene.spec.views.size())); }

ViewSetup make_view_setup(const LoadedScene& scene, int index, int width, int height) {
    if (index < 0 || index >= view_count(scene))
        throw Error("scene " + scene.spec.name + " has no view " + std::to_string(index));
    ViewSetup view;
    view.width = width;
    view.height = height;
    view.camera = scene.spec.views.empty() ? scene.scene.camera_or_default() : scene.spec.views[size_t(index)];
    const Box3f& bounds = scene.geometry.bounds;
    if (scene.spec.has_light) {
        view.light = scene.spec.light;
    } else {
        // The scene's first point light, else a point above the scene.
        bool found = false;
        for (const Light& light : scene.scene.lights) {
            if (light.type != LightType::Point) continue;
            view.light = light.position;
            found = true;
            break;
        }
        if (!found) view.light = bounds.center() + Vec3f(0.25f, 1.0f, 0.5f) * (0.75f * diagonal(scene));
    }
    view.ao_radius = scene.spec.ao_radius > 0.0f ? scene.spec.ao_radius : 0.02f * diagonal(scene);
    if (!(view.ao_radius > 0.0f)) view.ao_radius = 1.0f;
    return view;
}

}  // namespace rf::bench
