#include "bookmarks.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "rayforge/core/error.h"
#include "text.h"

namespace rf::viewer {
namespace {

using Json = nlohmann::json;

constexpr const char* kFormat = "rayforge-bookmarks";
constexpr int kVersion = 1;

Vec3f read_vec3(const Json& value, const std::string& where) {
    if (!value.is_array() || value.size() != 3) throw Error(where + ": expected an array of 3 numbers");
    Vec3f v;
    for (int i = 0; i < 3; ++i) {
        if (!value[size_t(i)].is_number()) throw Error(where + ": expected an array of 3 numbers");
        v[i] = value[size_t(i)].get<float>();
        if (!std::isfinite(v[i])) throw Error(where + ": numbers must be finite");
    }
    return v;
}

Bookmark read_bookmark(const Json& entry, const std::string& where) {
    if (!entry.is_object()) throw Error(where + ": expected an object");
    Bookmark b;
    if (!entry.contains("name") || !entry["name"].is_string() || entry["name"].get<std::string>().empty())
        throw Error(where + ": needs a non-empty \"name\"");
    b.name = entry["name"].get<std::string>();
    const std::string at = where + " '" + b.name + "'";
    if (entry.contains("scene")) {
        if (!entry["scene"].is_string()) throw Error(at + ": \"scene\" must be a string");
        b.scene = entry["scene"].get<std::string>();
    }
    if (!entry.contains("eye") || !entry.contains("target")) throw Error(at + ": needs \"eye\" and \"target\"");
    b.camera.eye = read_vec3(entry["eye"], at + " eye");
    b.camera.target = read_vec3(entry["target"], at + " target");
    if (entry.contains("up")) b.camera.up = read_vec3(entry["up"], at + " up");
    if (entry.contains("fov")) {
        if (!entry["fov"].is_number()) throw Error(at + ": \"fov\" must be a number");
        b.camera.vfov_degrees = entry["fov"].get<float>();
    }
    try {
        (void)CameraFrame::make(b.camera, 1, 1);
    } catch (const Error& e) {
        throw Error(at + ": " + e.what());
    }
    return b;
}

Json vec3(Vec3f v) { return Json::array({v.x, v.y, v.z}); }

}  // namespace

void Bookmarks::put(const Bookmark& bookmark) {
    for (Bookmark& b : items_)
        if (b.name == bookmark.name) {
            b = bookmark;
            return;
        }
    items_.push_back(bookmark);
}

bool Bookmarks::remove(const std::string& name) {
    const auto it = std::find_if(items_.begin(), items_.end(), [&](const Bookmark& b) { return b.name == name; });
    if (it == items_.end()) return false;
    items_.erase(it);
    return true;
}

const Bookmark* Bookmarks::find(const std::string& name) const {
    for (const Bookmark& b : items_)
        if (b.name == name) return &b;
    return nullptr;
}

Bookmarks Bookmarks::parse(const std::string& text, const std::string& path) {
    Json root;
    try {
        root = Json::parse(text);
    } catch (const Json::exception& e) {
        std::string what = e.what();
        std::replace(what.begin(), what.end(), '\n', ' ');
        throw Error(path + ": not valid JSON (" + what + ")");
    }
    if (!root.is_object()) throw Error(path + ": expected a JSON object");
    if (root.contains("format") && root["format"] != kFormat)
        throw Error(path + ": not a rayforge bookmarks file (format is not \"" + std::string(kFormat) + "\")");
    if (root.contains("version") && (!root["version"].is_number_integer() || root["version"].get<int>() > kVersion))
        throw Error(path + ": bookmarks version " + root["version"].dump() + " is newer than this rayforge reads (" +
                    std::to_string(kVersion) + ")");
    if (!root.contains("bookmarks") || !root["bookmarks"].is_array())
        throw Error(path + ": needs a \"bookmarks\" array");
    Bookmarks result;
    size_t index = 0;
    for (const Json& entry : root["bookmarks"])
        result.put(read_bookmark(entry, path + ": bookmark " + std::to_string(index++)));
    return result;
}

Bookmarks Bookmarks::load(const std::string& path) {
    return parse(read_text_file(path, "the bookmarks file"), path);
}

std::string Bookmarks::to_json() const {
    Json list = Json::array();
    for (const Bookmark& b : items_) {
        Json entry = {{"name", b.name},
                      {"eye", vec3(b.camera.eye)},
                      {"target", vec3(b.camera.target)},
                      {"up", vec3(b.camera.up)},
                      {"fov", b.camera.vfov_degrees}};
        if (!b.scene.empty()) entry["scene"] = b.scene;
        list.push_back(std::move(entry));
    }
    const Json root = {{"format", kFormat}, {"version", kVersion}, {"bookmarks", std::move(list)}};
    return root.dump(2) + "\n";
}

void Bookmarks::save(const std::string& path) const {
    const std::string tmp = path + ".tmp";
    {
        std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
        if (!out) throw Error(path + ": cannot write the bookmarks file");
        out << to_json();
        if (!out.flush()) throw Error(path + ": cannot write the bookmarks file");
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) throw Error(path + ": cannot replace the bookmarks file");
}

}  // namespace rf::viewer
