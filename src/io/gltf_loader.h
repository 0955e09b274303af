// Internal entry points of the glTF loader (src/io/gltf_loader.cpp) besides
// rf::load_gltf: a .gltf held in memory (builtin scenes generated as glTF).
#pragma once

#include <string>

#include "rayforge/io/scene_io.h"

namespace rf::io {

// A .gltf document (JSON, buffers as data URIs only); `name` is the scene's
// source and the file name in error messages. Throws rf::Error.
Scene load_gltf_text(const std::string& text, const std::string& name, const LoadOptions& options = {});

}  // namespace rf::io
