// The loader tests' check for a one-line error: the message rf::load_scene
// throws for a file, or "" when the file loads.
#pragma once

#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf::test {

inline std::string load_error(const std::string& path) {
    try {
        load_scene(path);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

}  // namespace rf::test
