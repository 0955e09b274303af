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

// PrimaryMorton ("primary-morton") is the primary set in Morton (Z) order
// of the pixel coordinates: the same rays, permuted (morton_pixel_order), as
// the published Aila-Laine figures trace them. It is reported beside the
// protocol's scanline primaries, never instead of them, and is not part of
// kAllRaySets (the protocol's five): it runs when named, and GPU rows add it
// to every primary set (bench_runner.h).
enum class RaySetKind : uint8_t { Primary, Shadow, Ao, Diffuse, Reflection, PrimaryMorton };

inline constexpr RaySetKind kAllRaySets[] = {RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Ao,
                                             RaySetKind::Diffuse, RaySetKind::Reflection};

const char* ray_set_name(RaySetKind kind);
std::optional<RaySetKind> parse_ray_set(const std::string& name);  // "primary", "shadow", ..., "primary-morton"
// Shadow and ao rays ask for any hit; the others for the closest hit.
bool is_any_hit(RaySetKind kind);

// Everything that fixes one view's rays.
struct ViewSetup {
    Camera camera;
    int width = 1024;
    int height = 768;
    Vec3f light;            // point light of the shadow set
    float ao_radius = 1.0f; // tmax of the ao set
    // Camera rays per pixel. The protocol's GPU rule is 4 jittered samples per
    // pixel, so that one set fills the device; the CPU traces 1 (the centre).
    int samples_per_pixel = 1;
};

struct RaySet {
    RaySetKind kind = RaySetKind::Primary;
    std::vector<Ray> rays;
};

// Seed of the hash behind every random number of the ray sets. Changing it
// changes every published figure, so it never changes.
inline constexpr uint32_t kRaySetSeed = 0x5EED2014u;
// Seed of the pixel jitter of samples s > 0 (a different seed, so the jitter
// is not correlated with the ao directions, which use kRaySetSeed).
inline constexpr uint32_t kPixelJitterSeed = 0x5EED2015u;
// Cosine-weighted directions per primary hit in the ao and diffuse sets.
inline constexpr int kAoSamplesPerHit = 8;

// Where camera sample `sample` of pixel `pixel` crosses that pixel, in
// [0, 1)^2 from its top-left corner: the centre (0.5, 0.5) for sample 0, the
// first two numbers of rf::RandomStream(pixel, sample, kPixelJitterSeed) otherwise.
Vec2f pixel_sample_position(uint32_t pixel, uint32_t sample);

// The primary set: view.samples_per_pixel rays per pixel, sample-major: ray
// s * width * height + p is sample s of pixel p (pixels in row-major order),
// so sample 0 is exactly the one-sample set of pixel centres.
RaySet make_primary_rays(const ViewSetup& view);

// The row-major indices of a width x height image's pixels in Morton order
// of (x, y), x in the even bits: every aligned 8x4 block of pixels is 32
// consecutive entries (one warp), every aligned 2^k x 2^k square a run.
// Pixels outside the largest power-of-two square are not skipped but keep
// their Morton rank among the image's pixels (the order of their codes).
std::vector<uint32_t> morton_pixel_order(int width, int height);

// The primary set of `view` with each sample's pixels in morton_pixel_order:
// ray s * pixels + i is sample s of pixel morton_pixel_order(...)[i].
RaySet make_morton_primary_rays(const RaySet& primary, const ViewSetup& view);

// The secondary sets, from the closest hits of the primary rays (found by
// `reference`, which must hold `geometry`). For every primary hit, in pixel order:
//  - the hit point is offset by 1e-4 x scene diagonal along the geometric
//    normal turned to face the incoming ray;
//  - shadow: one ray to view.light, any hit, tmax = distance to the light;
//  - ao: kAoSamplesPerHit cosine-weighted directions about that normal, any
//    hit, tmax = view.ao_radius; diffuse: the same directions, closest hit;
//  - reflection: the mirror direction about that normal, closest hit.
// Direction k of the primary ray of sample s of pixel p takes its two numbers
// from rf::RandomStream(p, s * kAoSamplesPerHit + k, kRaySetSeed) (PCG hash,
// src/math/random.h), so any run regenerates the identical arrays, and the
// one-sample sets do not change with samples_per_pixel. Secondary rays follow
// the order of their (scanline) primaries. Only the kinds listed are produced
// (in that order); PrimaryMorton is make_morton_primary_rays of the primaries.
std::vector<RaySet> make_ray_sets(const SceneGeometry& geometry, const Accel& reference, const ViewSetup& view,
                                  const std::vector<RaySetKind>& kinds);

}  // namespace rf::bench
