// Procedural massive scenes of unique geometry (docs/paged-scenes.md), streamed
// object by object to a sink so that no more than one object is ever held:
// `rayforge generate` writes them straight into the paged format.
//
// "terrain-statues": an fBm-displaced terrain cut into square tiles, and
// copies of the Stanford bunny and dragon (when `statue_dir` holds them)
// and of a procedural blob scattered on it, each copy with its own scale,
// rotation, subdivision level and noise displacement, so no two copies and
// no two pages are alike. "terrain": the terrain alone. "forest": the
// terrain with a few unique statue prototypes (half the triangles), each
// placed by many instances (the seed's clones: `instanced_triangles` more,
// the triangles the placements show). Everything is a pure function of the
// options (see massive_scene.cpp for the layout).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "rayforge/math/affine.h"
#include "rayforge/math/box.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/light.h"
#include "rayforge/scene/material.h"
#include "rayforge/scene/texture.h"

namespace rf::pack {

inline constexpr uint64_t kMinGeneratedTriangles = 1000;
inline constexpr uint64_t kMaxGeneratedTriangles = 16'000'000'000ull;
inline constexpr uint64_t kMinObjectTriangles = 1000;

struct GenerateOptions {
    std::string name = "terrain-statues";  // one of generator_names()
    uint64_t triangles = 4'000'000;        // target total; the result is within a few % of it
    uint64_t seed = 1;
    // A folder with stanford-bunny/bun_zipper.ply (or stanford-bunny.obj)
    // and stanford-dragon/dragon_vrip.ply; a statue whose file is missing
    // or unreadable is left out, and the procedural blob is always used.
    std::string statue_dir;
    uint64_t max_object_triangles = 2'000'000;  // no object the sink receives is larger
    // "forest": triangles shown by the instances (0: 25 times `triangles`).
    uint64_t instanced_triangles = 0;
};
inline constexpr uint64_t kMaxInstancedTriangles = 1'000'000'000'000ull;


// One object, in world space.
struct GeneratedObject {
    std::vector<Vec3f> positions;
    std::vector<Vec3f> normals;          // one per position, unit
    std::vector<Vec2f> uvs;              // one per position
    std::vector<uint32_t> indices;       // 3 per triangle
    std::vector<uint32_t> material_ids;  // one per triangle, index into GeneratedLook::materials

    [[nodiscard]] size_t triangle_count() const { return indices.size() / 3; }
};

// Where instanced content goes ("forest"): each prototype once, in its own
// space (prototype returns the id place takes), then its placements.
struct InstanceSink {
    std::function<uint32_t(const GeneratedObject&)> prototype;
    std::function<void(uint32_t prototype, const Affine3f& world_from_object)> place;
};

// Everything but the geometry: materials (textures referenced by index into
// `textures`), a camera looking over the terrain at the statues, one sun,
// a constant sky, and bounds that contain every object (exact in x and z,
// conservative in y).
struct GeneratedLook {
    std::vector<Material> materials;
    std::vector<Texture> textures;
    Camera camera;
    std::vector<Light> lights;
    Environment environment;
    Box3f bounds;
};

std::vector<std::string> generator_names();

// Cheap (no statue is loaded, no geometry made); throws rf::Error for
// options generate_scene would refuse.
GeneratedLook generated_look(const GenerateOptions& options);

// Calls sink(object) for each object in a fixed order (terrain tiles row by
// row, then the statues row by row) and progress(fraction) from 0 to 1.
// Returns the triangles emitted. Throws rf::Error for an unknown name, a
// triangle count outside [kMinGeneratedTriangles, kMaxGeneratedTriangles]
// or max_object_triangles below kMinObjectTriangles. Memory stays
// O(max_object_triangles) plus the statue sources and their subdivided
// topologies (about 24 bytes per subdivided triangle, at most 4/3 of
// max(max_object_triangles, source) per source).
// "forest": with `instances`, prototypes and placements go there; without,
// every placement is a world-space copy handed to `sink` (small scenes).
// Returns the unique triangles emitted.
uint64_t generate_scene(const GenerateOptions& options,
                        const std::function<void(const GeneratedObject&)>& sink,
                        const std::function<void(double)>& progress = {}, const InstanceSink* instances = nullptr);

}  // namespace rf::pack
