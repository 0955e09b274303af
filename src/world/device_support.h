// What each device can do for a world, decided here once for the library
// (and so for the CLI, the viewer, the bench and the Python module, which
// all make worlds):
//   - paged scenes render on the CPU (the device page manager answers
//     queries but renders no image yet);
//   - on a CUDA device the structure and the GPU kernel agree (the rule of
//     accel/build_options.h: whichever is not its default decides);
//   - adapt and clusters restructure trees on the host: CPU only;
//   - structures other than the BVH follow an animation by rebuilding.
// An explicit request a device cannot serve is one rf::Error; a default it
// cannot serve (a scene file's own update method) is replaced, with a note.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "rayforge/world.h"

namespace rf {

enum class WorldKind : uint8_t { Still, Animated, Paged };

// The options a world is built with, once the device's rules are applied.
struct WorldPlan {
    BuildOptions build;               // build.device = the world's device
    UpdateOptions update;             // update.method always set (animated worlds)
    bool dynamic_bvh = false;         // a DynamicAccel follows the motion (an animated BVH, or a still one
                                      // given a method); otherwise a change rebuilds
    std::vector<std::string> notes;   // defaults replaced, one line each
};

// The plan for a scene of `kind` whose file names `scene_update` as its
// update method (if any): option ranges, the rules above. Whether the device
// can be used at all is check_world_options' (rayforge/world.h) question,
// so the rules can be checked (and tested) without the device.
WorldPlan plan_world(const WorldOptions& options, WorldKind kind, const std::optional<std::string>& scene_update);

}  // namespace rf
