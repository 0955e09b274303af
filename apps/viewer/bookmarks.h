// Camera bookmarks: named cameras saved to and loaded from a small JSON
// file, e.g.
//   {"format": "rayforge-bookmarks", "version": 1,
//    "bookmarks": [{"name": "nave", "scene": "sponza",
//                   "eye": [1100, 180, -40], "target": [-1000, 320, 40], "up": [0, 1, 0], "fov": 60}]}
// "scene" is optional (the scene the view was taken in); unknown keys are
// ignored. Reading checks every field and names the file and the bookmark
// in its one-line error.
#pragma once

#include <string>
#include <vector>

#include "rayforge/scene/camera.h"

namespace rf::viewer {

struct Bookmark {
    std::string name;
    std::string scene;  // "" = any
    Camera camera;
};

class Bookmarks {
public:
    [[nodiscard]] const std::vector<Bookmark>& all() const { return items_; }
    // Adds or replaces the bookmark of that name.
    void put(const Bookmark& bookmark);
    bool remove(const std::string& name);
    // nullptr when there is none of that name.
    [[nodiscard]] const Bookmark* find(const std::string& name) const;

    // Throws rf::Error for an unreadable or malformed file; a missing file
    // is an error too (the caller decides whether that matters).
    static Bookmarks load(const std::string& path);
    // Parses the file's text; `path` names it in errors.
    static Bookmarks parse(const std::string& text, const std::string& path);
    [[nodiscard]] std::string to_json() const;
    void save(const std::string& path) const;  // throws rf::Error when it cannot write

private:
    std::vector<Bookmark> items_;
};

}  // namespace rf::viewer
