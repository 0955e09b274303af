// Procedural animated scenes (docs/animation.md), analogues of the UNC dynamic
// benchmarks Garanzha 2014 measures (3.33 s, 100 frames at 30 fps): "explode" (a
// noise-displaced rock cut into connected fragments that fly apart and spin),
// "cloth" (a cloth grid draping over a ball, simulated at load time) and
// "nbody" (small rigid bodies bursting out of one dense heap in a box). Each
// is generated from a seed, needs no files, and describes its motion in
// Scene::animation (node tracks for rigid motion, vertex keyframes for the
// cloth); Scene::set_time evaluates it.
//
// Names (after "builtin:"): NAME[@SIZE][#SEED]. SIZE is the scene's total
// triangle count, an integer with an optional k (x1000) or m (x1000000)
// suffix, e.g. "explode@800k" or "cloth@1.5m"; SEED an unsigned integer.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rayforge/scene/scene.h"

namespace rf {

inline constexpr size_t kExplodeDefaultTriangles = 250000;  // Garanzha 2014's Exploding Dragon: 252K
inline constexpr size_t kClothDefaultTriangles = 92000;     // Cloth on ball: 92K
inline constexpr size_t kNbodyDefaultTriangles = 146000;    // Colliding N bodies: 146K
inline constexpr uint32_t kAnimatedSceneDefaultSeed = 2101u;
inline constexpr int kAnimatedSceneFrames = 100;            // keys at frame / 30 s, 0 .. 3.3 s
inline constexpr float kAnimatedSceneFps = 30.0f;
inline constexpr size_t kAnimatedSceneMinTriangles = 1000;
inline constexpr size_t kAnimatedSceneMaxTriangles = 2000000;

struct AnimatedSceneSpec {
    std::string kind;      // "explode", "cloth" or "nbody"
    size_t triangles = 0;  // requested total; 0: the kind's default
    uint32_t seed = kAnimatedSceneDefaultSeed;
};

// The kinds, for builtin_scene_names().
std::vector<std::string> animated_scene_names();
// Whether `name` (without "builtin:") is NAME[@SIZE][#SEED] of an animated kind.
bool is_animated_scene_name(const std::string& name);
// Parses such a name; throws rf::Error (one line naming it) on a bad suffix
// or a size outside [kAnimatedSceneMinTriangles, kAnimatedSceneMaxTriangles].
AnimatedSceneSpec parse_animated_scene_name(const std::string& name);
// make_builtin_scene's hook: the scene `name` describes.
Scene make_animated_scene(const std::string& name);

// The makers (triangles = the requested total; 0: the default). The scene is
// at time 0 (its instances and meshes are frame 0) and not yet finalized.
Scene make_explode_scene(size_t triangles = 0, uint32_t seed = kAnimatedSceneDefaultSeed);
Scene make_cloth_scene(size_t triangles = 0, uint32_t seed = kAnimatedSceneDefaultSeed);
Scene make_nbody_scene(size_t triangles = 0, uint32_t seed = kAnimatedSceneDefaultSeed);

}  // namespace rf
