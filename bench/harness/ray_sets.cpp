#include "ray_sets.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "math/random.h"
#include "render/sampling.h"

namespace rf::bench {

const char* ray_set_name(RaySetKind kind) {
    switch (kind) {
        case RaySetKind::Primary: return "primary";
        case RaySetKind::Shadow: return "shadow";
        case RaySetKind::Ao: return "ao";
        case RaySetKind::Diffuse: return "diffuse";
        case RaySetKind::Reflection: return "reflection";
        case RaySetKind::PrimaryMorton: return "primary-morton";
    }
    return "?";
}

std::optional<RaySetKind> parse_ray_set(const std::string& name) {
    for (RaySetKind kind : kAllRaySets)
        if (name == ray_set_name(kind)) return kind;
    if (name == ray_set_name(RaySetKind::PrimaryMorton)) return RaySetKind::PrimaryMorton;
    return std::nullopt;
}

bool is_any_hit(RaySetKind kind) { return kind == RaySetKind::Shadow || kind == RaySetKind::Ao; }

Vec2f pixel_sample_position(uint32_t pixel, uint32_t sample) {
    if (sample == 0) return {0.5f, 0.5f};
    RandomStream random(pixel, sample, kPixelJitterSeed);
    return random.next2();
}

RaySet make_primary_rays(const ViewSetup& view) {
    if (view.samples_per_pixel < 1) throw Error("ray sets: samples per pixel must be at least 1");
    const CameraFrame frame = CameraFrame::make(view.camera, view.width, view.height);
    RaySet set;
    set.kind = RaySetKind::Primary;
    const size_t pixels = size_t(view.width) * size_t(view.height);
    set.rays.resize(pixels * size_t(view.samples_per_pixel));
    // One task per (sample, row band); rows of every sample in parallel.
    const int rows = view.height * view.samples_per_pixel;
    parallel::for_range(0, rows, 8, [&](int r0, int r1) {
        for (int r = r0; r < r1; ++r) {
            const int sample = r / view.height, y = r % view.height;
            for (int x = 0; x < view.width; ++x) {
                const size_t pixel = size_t(y) * size_t(view.width) + size_t(x);
                const Vec2f at = pixel_sample_position(uint32_t(pixel), uint32_t(sample));
                set.rays[size_t(sample) * pixels + pixel] =
                    frame.generate(float(x) + at.x, float(y) + at.y, view.width, view.height);
            }
        }
    });
    return set;
}

namespace {

// The low 16 bits of v moved to the even bits 0, 2, ... 30.
uint32_t spread_bits_by_2(uint32_t v) {
    v &= 0xFFFFu;
    v = (v | (v << 8)) & 0x00FF00FFu;
    v = (v | (v << 4)) & 0x0F0F0F0Fu;
    v = (v | (v << 2)) & 0x33333333u;
    v = (v | (v << 1)) & 0x55555555u;
    return v;
}

}  // namespace

std::vector<uint32_t> morton_pixel_order(int width, int height) {
    if (width < 1 || height < 1 || width > 65536 || height > 65536)
        throw Error("ray sets: Morton order needs image sides in [1, 65536]");
    const size_t pixels = size_t(width) * size_t(height);
    if (pixels > size_t(UINT32_MAX)) throw Error("ray sets: too many pixels for a Morton order");
    std::vector<std::pair<uint32_t, uint32_t>> keyed(pixels);  // (code, pixel); codes are distinct
    for (uint32_t y = 0; y < uint32_t(height); ++y)
        for (uint32_t x = 0; x < uint32_t(width); ++x) {
            const uint32_t pixel = y * uint32_t(width) + x;
            keyed[pixel] = {spread_bits_by_2(x) | (spread_bits_by_2(y) << 1), pixel};
        }
    std::sort(keyed.begin(), keyed.end());
    std::vector<uint32_t> order(pixels);
    for (size_t i = 0; i < pixels; ++i) order[i] = keyed[i].second;
    return order;
}

RaySet make_morton_primary_rays(const RaySet& primary, const ViewSetup& view) {
    const std::vector<uint32_t> order = morton_pixel_order(view.width, view.height);
    const size_t pixels = order.size();
    if (primary.kind != RaySetKind::Primary || primary.rays.size() != pixels * size_t(view.samples_per_pixel))
        throw Error("ray sets: the Morton set needs the view's primary set");
    RaySet set;
    set.kind = RaySetKind::PrimaryMorton;
    set.rays.resize(primary.rays.size());
    for (size_t s = 0; s < size_t(view.samples_per_pixel); ++s)
        for (size_t i = 0; i < pixels; ++i) set.rays[s * pixels + i] = primary.rays[s * pixels + order[i]];
    return set;
}

namespace {

// Where a secondary ray starts and which way the surface faces the viewer.
struct SurfaceSample {
    Vec3f origin;
    Vec3f normal;  // unit geometric normal, facing the primary ray
};

SurfaceSample surface_sample(const Triangle& tri, const Ray& ray, const Hit& hit, float offset) {
    Vec3f n = tri.geometric_normal();
    const float len = length(n);
    // Degenerate triangles never produce hits, but guard the division anyway.
    n = len > 0.0f ? n * (1.0f / len) : Vec3f(0, 0, 1);
    if (dot(n, ray.dir) > 0.0f) n = -n;
    return {ray.org + ray.dir * hit.t + n * offset, n};
}

size_t rays_per_hit(RaySetKind kind) {
    return (kind == RaySetKind::Ao || kind == RaySetKind::Diffuse) ? size_t(kAoSamplesPerHit) : 1;
}

}  // namespace

std::vector<RaySet> make_ray_sets(const SceneGeometry& geometry, const Accel& reference, const ViewSetup& view,
                                  const std::vector<RaySetKind>& kinds) {
    if (!(view.ao_radius > 0.0f) || !std::isfinite(view.ao_radius))
        throw Error("ray sets: the ao radius must be a positive number");
    RaySet primary = make_primary_rays(view);
    std::vector<Hit> hits(primary.rays.size());
    reference.intersect(primary.rays, hits);

    // Slot of each hit among all hits, so parallel generation keeps pixel order.
    std::vector<uint32_t> hit_slot(hits.size());
    uint32_t hit_count = 0;
    for (size_t p = 0; p < hits.size(); ++p) {
        hit_slot[p] = hit_count;
        hit_count += hits[p].found() ? 1 : 0;
    }
    const float offset = 1e-4f * length(geometry.bounds.extent());
    const size_t pixels = size_t(view.width) * size_t(view.height);

    std::vector<RaySet> sets;
    for (RaySetKind kind : kinds) {
        if (kind == RaySetKind::Primary) {
            sets.push_back(primary);
            continue;
        }
        if (kind == RaySetKind::PrimaryMorton) {
            sets.push_back(make_morton_primary_rays(primary, view));
            continue;
        }
        RaySet set;
        set.kind = kind;
        const size_t per_hit = rays_per_hit(kind);
        set.rays.resize(size_t(hit_count) * per_hit);
        parallel::for_range(size_t(0), hits.size(), size_t(1024), [&](size_t lo, size_t hi) {
            for (size_t p = lo; p < hi; ++p) {
                if (!hits[p].found()) continue;
                const Ray& eye_ray = primary.rays[p];
                const SurfaceSample s = surface_sample(geometry.triangles[hits[p].prim], eye_ray, hits[p], offset);
                Ray* out = &set.rays[size_t(hit_slot[p]) * per_hit];
                switch (kind) {
                    case RaySetKind::Shadow: {
                        const Vec3f to_light = view.light - s.origin;
                        const float distance = length(to_light);
                        out->org = s.origin;
                        out->dir = distance > 0.0f ? to_light * (1.0f / distance) : s.normal;
                        out->tmin = 0.0f;
                        out->tmax = distance;
                        break;
                    }
                    case RaySetKind::Ao:
                    case RaySetKind::Diffuse: {
                        const Frame frame = Frame::from_normal(s.normal);
                        // Primary p is sample p / pixels of pixel p % pixels.
                        const uint32_t pixel = uint32_t(p % pixels);
                        const uint32_t first = uint32_t(p / pixels) * uint32_t(kAoSamplesPerHit);
                        for (uint32_t sample = 0; sample < uint32_t(kAoSamplesPerHit); ++sample) {
                            RandomStream random(pixel, first + sample, kRaySetSeed);
                            out[sample].org = s.origin;
                            out[sample].dir = frame.to_world(sample_cosine_hemisphere(random.next2()));
                            out[sample].tmin = 0.0f;
                            out[sample].tmax = kind == RaySetKind::Ao ? view.ao_radius : kInfinity;
                        }
                        break;
                    }
                    case RaySetKind::Reflection: {
                        const Vec3f d = eye_ray.dir;
                        out->org = s.origin;
                        out->dir = normalize(d - s.normal * (2.0f * dot(d, s.normal)));
                        out->tmin = 0.0f;
                        out->tmax = kInfinity;
                        break;
                    }
                    case RaySetKind::Primary:
                    case RaySetKind::PrimaryMorton: break;
                }
            }
        });
        sets.push_back(std::move(set));
    }
    return sets;
}

}  // namespace rf::bench
