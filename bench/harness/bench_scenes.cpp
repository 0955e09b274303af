#include "bench_scenes.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstring>
#include <utility>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "render/sampling.h"

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

// NAME-xN: copies 5% of the model's size apart, framed for 4:3 images.
constexpr float kCopySpacing = 1.05f;
constexpr double kCopyFrameAspect = 4.0 / 3.0;

// "12M" -> 12000000 (K, M, G: powers of 1000); 0 when malformed.
uint64_t parse_count(const std::string& text) {
    if (text.empty() || !std::isdigit(static_cast<unsigned char>(text[0]))) return 0;
    size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        return 0;
    }
    const std::string suffix = text.substr(used);
    const double scale = suffix.empty() ? 1.0 : suffix == "K" || suffix == "k" ? 1e3 : suffix == "M" ? 1e6
                         : suffix == "G" ? 1e9 : 0.0;
    const double count = value * scale;
    return count >= 1.0 && count < 1e15 ? uint64_t(count + 0.5) : 0;
}

// generate:GENERATOR@COUNT[#SEED] into its options (rf::Error when malformed).
GenerateOptions parse_generated_name(const std::string& name) {
    const std::string body = name.substr(std::strlen(kGeneratedScenePrefix));
    const size_t at = body.find('@'), hash = body.find('#');
    const auto fail = [&](const std::string& why) {
        return Error("scene '" + name + "': " + why + " (expected generate:GENERATOR@COUNT[#SEED], e.g. " +
                     "generate:terrain-statues@12M)");
    };
    if (at == std::string::npos || (hash != std::string::npos && hash < at)) throw fail("no @COUNT");
    GenerateOptions options;
    options.name = body.substr(0, at);
    const std::vector<std::string> known = generated_scene_names();
    if (std::find(known.begin(), known.end(), options.name) == known.end()) {
        std::string list;
        for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
        throw fail("unknown generator '" + options.name + "' (known: " + list + ")");
    }
    options.triangles = parse_count(body.substr(at + 1, hash == std::string::npos ? std::string::npos : hash - at - 1));
    if (options.triangles == 0) throw fail("bad triangle count");
    if (hash != std::string::npos) {
        const std::string seed = body.substr(hash + 1);
        if (seed.empty() || seed.find_first_not_of("0123456789") != std::string::npos || seed.size() > 19)
            throw fail("bad seed '" + seed + "'");
        options.seed = std::stoull(seed);
    }
    return options;
}

// "dragon-x15" -> ("dragon", 15); copies 0 when `name` has no -xN suffix.
std::pair<std::string, int> split_copies(const std::string& name) {
    const size_t dash = name.rfind("-x");
    if (dash == std::string::npos || dash == 0 || dash + 2 >= name.size()) return {name, 0};
    const std::string digits = name.substr(dash + 2);
    if (digits.size() > 3 || digits.find_first_not_of("0123456789") != std::string::npos) return {name, 0};
    return {name.substr(0, dash), std::stoi(digits)};
}

}  // namespace

int scene_copy_columns(const Box3f& model, int copies) {
    const Vec3f step = model.extent() * kCopySpacing;
    int best = 1;
    double best_fill = -1.0;
    for (int columns = 1; columns <= copies; ++columns) {
        const double width = double(columns) * std::max(double(step.x), 1e-30);
        const double height = double((copies + columns - 1) / columns) * std::max(double(step.y), 1e-30);
        const double frame = std::max(width, height * kCopyFrameAspect) * std::max(height, width / kCopyFrameAspect);
        const double fill = width * height / frame;  // the grid's share of the 4:3 frame around it
        if (fill > best_fill * (1.0 + 1e-9)) {
            best_fill = fill;
            best = columns;
        }
    }
    return best;
}

Vec3f scene_copy_offset(const Box3f& model, int index, int copies) {
    const int columns = scene_copy_columns(model, copies);
    const Vec3f step = model.extent() * kCopySpacing;
    return {step.x * float(index % columns), -step.y * float(index / columns), 0.0f};
}

Camera scene_copies_camera(const Box3f& grid) {
    Camera camera;
    const Vec3f extent = grid.extent();
    const float tan_half = std::tan(0.5f * camera.vfov_degrees * kPi / 180.0f);
    const float half_height = 0.5f * std::max(extent.y, extent.x / float(kCopyFrameAspect));
    camera.target = grid.center();
    camera.eye = camera.target + Vec3f(0.0f, 0.0f, 0.5f * extent.z + 1.02f * half_height / tan_half);
    return camera;
}

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
    if (name.rfind(kGeneratedScenePrefix, 0) == 0) {
        (void)parse_generated_name(name);  // checked now, generated when loaded
        spec.name = name;
        spec.path = name;
        std::error_code ec;
        if (!scenes_dir.empty() && fs::is_directory(fs::path(scenes_dir) / "stanford-dragon", ec))
            spec.statue_dir = scenes_dir;
        return spec;
    }
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
    const bool listed = views.contains("scenes") && views["scenes"].contains(name);
    if (const auto [base, copies] = split_copies(name); !listed && copies > 0) {
        if (copies < 2 || copies > kMaxSceneCopies)
            throw Error("scene '" + name + "': copies must be from 2 to " + std::to_string(kMaxSceneCopies));
        SceneSpec copied;
        try {
            copied = resolve_scene(base, scenes_dir);
        } catch (const Error& e) {
            throw Error("scene '" + name + "' (copies of '" + base + "'): " + e.what());
        }
        copied.name = name;
        copied.copies = copies;
        copied.views.clear();      // the model's views do not frame the grid: scene_copies_camera does
        copied.has_light = false;  // nor does its light light it: a light above the grid
        return copied;
    }
    if (!listed) {
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

namespace {

// Every instance of `scene` `copies` times, copy i moved by scene_copy_offset.
void replicate_instances(Scene& scene, int copies) {
    if (scene.animated()) throw Error("scene copies (NAME-xN): not of an animated scene");
    const Box3f model = SceneGeometry::build(scene).bounds;
    const std::vector<Instance> originals = scene.instances;
    Box3f grid = model;
    for (int copy = 1; copy < copies; ++copy) {
        const Vec3f offset = scene_copy_offset(model, copy, copies);
        const Affine3f move = Affine3f::translation(offset);
        for (Instance instance : originals) {
            instance.transform = move * instance.transform;
            scene.instances.push_back(instance);
        }
        grid.extend(model.lo + offset);
        grid.extend(model.hi + offset);
    }
    scene.camera = scene_copies_camera(grid);  // a file's camera frames one copy
}

}  // namespace

LoadedScene load_bench_scene(const SceneSpec& spec) {
    LoadedScene loaded;
    loaded.spec = spec;
    const auto start = std::chrono::steady_clock::now();
    if (spec.path.rfind(kGeneratedScenePrefix, 0) == 0) {
        GenerateOptions generate = parse_generated_name(spec.path);
        generate.statue_dir = spec.statue_dir;
        loaded.scene = generate_scene(generate);
    } else {
        LoadOptions options;
        options.load_textures = false;  // the bench traces geometry only
        loaded.scene = load_scene(spec.path, options);
    }
    if (spec.copies > 1) replicate_instances(loaded.scene, spec.copies);
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
