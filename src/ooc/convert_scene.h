// An in-memory scene written as a paged scene file, one instance at a time:
// a mesh placed once becomes a world-space object (§6.3.1 (h)), a mesh
// placed by several instances one object-space object placed by instances
// (the seed's clones). What the paged renderer cannot do is reported in
// `notes`: cut-outs and blending become opaque, an environment map becomes
// its constant colour, normal maps lose their tangent frames.
#pragma once

#include <string>
#include <vector>

#include "ooc/pack_writer.h"
#include "rayforge/scene/scene.h"

namespace rf::pack {

struct ConvertResult {
    PackSummary summary;
    std::vector<std::string> notes;
};

// Everything but the geometry: textures and materials (made opaque, with
// notes), lights, `camera`, the environment.
void write_scene_look(const Scene& scene, const Camera& camera, PackWriter& writer, std::vector<std::string>& notes);

ConvertResult convert_scene(const Scene& scene, const std::string& path, const PackWriterOptions& options,
                            const ProgressCallback& progress = {});

}  // namespace rf::pack
