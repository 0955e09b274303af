// rf::load_scene: picks the loader from a "builtin:NAME" prefix or from the
// file's (case-insensitive) extension.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf {

namespace {

constexpr const char* kBuiltinPrefix = "builtin:";

std::string lowercase_extension(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

}  // namespace

Scene load_scene(const std::string& path_or_name, const LoadOptions& options) {
    const std::string prefix = kBuiltinPrefix;
    if (path_or_name.rfind(prefix, 0) == 0) {
        Scene scene = make_builtin_scene(path_or_name.substr(prefix.size()));
        scene.finalize();
        return scene;
    }
    const std::string ext = lowercase_extension(path_or_name);
    Scene scene;
    if (ext == ".obj") scene = load_obj(path_or_name, options);
    else if (ext == ".gltf" || ext == ".glb") scene = load_gltf(path_or_name, options);
    else if (ext == ".ply") scene = load_ply(path_or_name, options);
    else if (ext == ".json") scene = load_json_scene(path_or_name, options);
    else if (ext == ".aff") scene = load_aff(path_or_name, options);
    else {
        std::error_code ec;
        if (!std::filesystem::exists(path_or_name, ec)) throw file_error(path_or_name, 0, "no such file");
        throw file_error(path_or_name, 0,
                         "unsupported scene format '" + ext +
                             "' (expected .obj, .gltf, .glb, .ply, .aff, .json or builtin:NAME)");
    }
    scene.finalize();
    return scene;
}

}  // namespace rf
