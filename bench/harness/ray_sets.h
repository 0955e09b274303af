// The benchmark's ray sets (../shared/docs/BENCHMARK-PROTOCOL.md): generated
// once, before any timing, and handed unchanged to every structure and to the
// Embree peer, so every figure is measured on identical rays.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::bench {

enum class RaySetKind : uint8_t { Primary, Shadow, Ao, Diffuse, Reflection };

inline constexpr RaySetKind kAllRaySets[] = {RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Ao,
                                             RaySetKind::Diffuse, RaySetKind::Reflection};

const char* ray_set_name(RaySetKind kind);
std::optional<RaySetKind> parse_ray_set(const std::string& name);  // "primary", "shadow", ...
// Shadow and ao rays ask for any hit; the others for the closest hit.
bool is_any_hit(RaySetKind kind);

// Everything that fixes one view's rays.
struct ViewSetup {
    Camera camera;
    int width = 1024;
    int height = 768;
    Vec3f light;            // point light of the shadow set
    float ao_radius = 1.0f; // tmax of the ao set
};

struct RaySet {
    RaySetKind kind = RaySetKind::Primary;
    std::vector<Ray> rays;
};

// Seed of the hash behind every random number of the ray sets. Changing it
// changes every published figure, so it never changes.
inline constexpr uint32_t kRaySetSeed = 0x5EED2014u;
// Cosine-weighted directions per primary hit in the ao and diffuse sets.
inline constexpr int kAoSamplesPerHit = 8;

// The primary set: one ray per pixel centre, pixels in row-major order.
RaySet make_primary_rays(const ViewSetup& view);

// The secondary sets, from the closest hits of the primary rays (found by
// `reference`, which must hold `geometry`). For every primary hit, in pixel order:
//  - the hit point is offset by 1e-4 x scene diagonal along the geometric
//    normal turned to face the incoming ray;
//  - shadow: one ray to view.light, any hit, tmax = distance to the light;
//  - ao: kAoSamplesPerHit cosine-weighted directions about that normal, any
//    hit, tmax = view.ao_radius; diffuse: the same directions, closest hit;
//  - reflection: the mirror direction about that normal, closest hit.
// Sample s of pixel p takes its two numbers from rf::RandomStream(p, s,
// kRaySetSeed) (PCG hash, src/render/random.h), so any run regenerates the
// identical arrays. Only the kinds listed are produced (in that order).
std::vector<RaySet> make_ray_sets(const SceneGeometry& geometry, const Accel& reference, const ViewSetup& view,
                                  const std::vector<RaySetKind>& kinds);

}  // namespace rf::bench
