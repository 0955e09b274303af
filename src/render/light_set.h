// Everything in a scene that emits, as one plain view the integrators share
// on both backends: analytic lights, the emissive triangles (area lights)
// and the environment, with a table that picks one of them in proportion to
// a rough power estimate (the light-selection step of next-event estimation,
// cf. Pharr, Jakob, Humphreys, PBRT 3rd ed. §14.3, "power" light distribution).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/core/host_device.h"
#include "core/assert.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/light.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "render/area_lights.h"
#include "render/environment_map.h"
#include "render/material_eval.h"

namespace rf {

struct LightSet {
    const Light* lights = nullptr; uint32_t light_count = 0;   // analytic lights
    EmitterTable emitters;            // emissive triangles, `triangles` sorted ascending (see emitter_index)
    const Triangle* triangles = nullptr;
    EnvironmentLight environment;
    // Entries: lights 0..L-1, then the area group (if any emitter), then the
    // environment (if it emits). cdf[i] = probability of entries 0..i; cdf[count-1] = 1.
    const float* selection_cdf = nullptr; uint32_t selection_count = 0;
    Vec3f scene_center{0}; float scene_radius = 1;  // bounding sphere, for directional lights and the environment

    [[nodiscard]] RF_HDI bool has_area_lights() const { return emitters.count > 0; }
    // Selection entry of the area group / the environment; selection_count when absent.
    [[nodiscard]] RF_HDI uint32_t area_entry() const {
        return has_area_lights() ? light_count : selection_count;
    }
    [[nodiscard]] RF_HDI uint32_t environment_entry() const {
        uint32_t i = light_count + (has_area_lights() ? 1u : 0u);
        return i < selection_count ? i : selection_count;
    }

    // Probability of choosing selection entry i (0 for an absent entry).
    [[nodiscard]] RF_HDI float selection_probability(uint32_t i) const {
        if (i >= selection_count) return 0.0f;
        return selection_cdf[i] - (i > 0 ? selection_cdf[i - 1] : 0.0f);
    }

    // The entry whose cdf interval holds u in [0, 1), its probability, and
    // u rescaled to [0, 1) within that interval (to be reused downstream).
    // Requires selection_count > 0.
    RF_HDI uint32_t select(float u, float& probability, float& u_remapped) const {
        RF_ASSERT(selection_count > 0, "a light selected from an empty light set");
        uint32_t lo = 0, hi = selection_count - 1;
        while (lo < hi) {  // first i with cdf[i] > u (skips zero-probability entries)
            uint32_t mid = (lo + hi) / 2;
            if (selection_cdf[mid] > u) hi = mid;
            else lo = mid + 1;
        }
        float start = lo > 0 ? selection_cdf[lo - 1] : 0.0f;
        probability = selection_cdf[lo] - start;
        u_remapped = probability > 0.0f ? fminf((u - start) / probability, 0.99999994f) : 0.0f;
        if (!(u_remapped >= 0.0f)) u_remapped = 0.0f;
        return lo;
    }

    // Position of flat triangle `prim` in the emitter table (binary search
    // over the sorted triangle list), or emitters.count if it is not there.
    [[nodiscard]] RF_HDI uint32_t emitter_index(uint32_t prim) const {
        uint32_t lo = 0, hi = emitters.count;
        while (lo < hi) {  // first i with triangles[i] >= prim
            uint32_t mid = (lo + hi) / 2;
            if (emitters.triangles[mid] < prim) lo = mid + 1;
            else hi = mid;
        }
        return (lo < emitters.count && emitters.triangles[lo] == prim) ? lo : emitters.count;
    }
};

// Power estimates used for selection (exposed for tests and diagnostics).
float analytic_light_power(const Light& light, float scene_radius);
// Emissive triangle `prim` over pi (flux of a Lambertian emitter / pi): area
// x luminance of its emission (the texture's mean over the triangle's uvs
// when it has one) x 2 when both faces emit. `textures` as the scene view's.
double emitter_power(const Scene& scene, const SceneGeometry& geometry, const ShadingMaterial& m,
                     std::span<const MipTextureView> textures, uint32_t prim);

// Host owner of the tables a LightSet views. `scene`, `geometry` and their
// textures must outlive it; the view stays valid when the owner is moved.
class HostLightSet {
public:
    // materials[i] is the shading form of scene material i (ids out of range
    // use 0); textures[i] the view of scene texture i, with its mip chain
    // (empty: single-level views of scene.textures).
    HostLightSet(const Scene& scene, const SceneGeometry& geometry, const std::vector<ShadingMaterial>& materials,
                 std::span<const MipTextureView> textures = {});
    HostLightSet(const HostLightSet&) = delete;
    HostLightSet& operator=(const HostLightSet&) = delete;
    HostLightSet(HostLightSet&&) = default;
    HostLightSet& operator=(HostLightSet&&) = default;

    [[nodiscard]] const LightSet& view() const { return view_; }

private:
    std::vector<uint32_t> emitter_triangles_;
    std::vector<float> emitter_cdf_;
    EnvironmentDistribution environment_;
    std::vector<float> selection_cdf_;
    LightSet view_;
};

}  // namespace rf
