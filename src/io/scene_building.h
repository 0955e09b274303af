// Small pieces the procedural scenes share (builtin_scenes.cpp,
// animated_scenes.cpp): appending materials and meshes, and the benchmark
// scenes' sun and sky (defined in builtin_scenes.cpp).
#pragma once

#include <cstdint>
#include <utility>

#include "rayforge/scene/scene.h"

namespace rf::io {

inline uint32_t add_material(Scene& scene, Material material) {
    scene.materials.push_back(std::move(material));
    return uint32_t(scene.materials.size() - 1);
}

inline uint32_t add_mesh(Scene& scene, Mesh mesh) {
    scene.meshes.push_back(std::move(mesh));
    return uint32_t(scene.meshes.size() - 1);
}

// A sun and a dim sky: the lighting the benchmark scenes share.
void add_sun_and_sky(Scene& scene, Vec3f sun_direction);

}  // namespace rf::io
