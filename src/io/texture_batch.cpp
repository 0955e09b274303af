#include "io/texture_batch.h"

#include <iostream>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"

namespace rf {

std::vector<std::optional<Texture>> decode_textures(const std::vector<std::string>& paths,
                                                    const std::string& fallback) {
    std::vector<std::optional<Texture>> decoded(paths.size());
    std::vector<std::string> failures(paths.size());  // one slot per task: no sharing
    parallel::for_each_index(size_t(0), paths.size(), [&](size_t i) {
        try {
            decoded[i] = load_texture(paths[i], TextureEncoding::Srgb8);
        } catch (const Error& e) {
            failures[i] = e.what();
        }
    });
    for (const std::string& failure : failures)
        if (!failure.empty()) std::cerr << "rayforge: warning: " << failure << "; using " << fallback << '\n';
    return decoded;
}

}  // namespace rf
