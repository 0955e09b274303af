// Parallel decoding of the texture files a scene loader collected (OBJ/MTL,
// BART AFF). A file that cannot be decoded is not an error for the scene:
// it becomes one warning line and an empty slot, and the material keeps its
// own colour.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "rayforge/scene/texture.h"

namespace rf {

// decoded[i] holds paths[i]'s texture (8-bit data as sRGB), or nothing when
// it failed; each failure prints "rayforge: warning: <reason>; using
// <fallback>".
std::vector<std::optional<Texture>> decode_textures(const std::vector<std::string>& paths,
                                                    const std::string& fallback);

}  // namespace rf
