// Telling a paged scene file by its first bytes (rf::is_paged_scene_file),
// apart from the reader so that what only decides by it (the world's device
// rules, the viewer's option checks and their fuzz target) needs no reader.
#include <cstring>
#include <fstream>

#include "ooc/pack_format.h"
#include "rayforge/ooc/paged_scene.h"

namespace rf {

bool is_paged_scene_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    char magic[sizeof(pack::kMagic)] = {};
    return in.read(magic, sizeof(magic)) && std::memcmp(magic, pack::kMagic, sizeof(magic)) == 0;
}

}  // namespace rf
