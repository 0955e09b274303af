// Builds the light-selection tables: emissive triangles by power (area x
// luminance of the emission factor), the environment's distribution, and
// one cdf over analytic lights, the area group and the environment.
#include "render/light_set.h"

#include <algorithm>
#include <cmath>

#include "math/color.h"
#include "render/sampling.h"

namespace rf {
namespace {

// Non-negative finite power, 0 otherwise.
double usable(double p) { return std::isfinite(p) && p > 0.0 ? p : 0.0; }

}  // namespace

float analytic_light_power(const Light& light, float scene_radius) {
    double intensity = double(light.intensity) * double(luminance(light.color));
    switch (light.type) {
        case LightType::Point:
            return float(usable(4.0 * kPi * intensity));
        case LightType::Spot:
            return float(usable(2.0 * kPi * (1.0 - std::cos(double(light.outer_cone_radians))) * intensity));
        case LightType::Directional:
        default:  // irradiance through the scene's cross-section
            return float(usable(intensity * kPi * double(scene_radius) * double(scene_radius)));
    }
}

HostLightSet::HostLightSet(const Scene& scene, const SceneGeometry& geometry,
                           const std::vector<ShadingMaterial>& materials)
    : environment_(scene) {
    LightSet& v = view_;
    v.lights = scene.lights.data();
    v.light_count = uint32_t(scene.lights.size());
    v.triangles = geometry.triangles.data();
    v.environment = environment_.light();

    if (!geometry.bounds.is_empty()) {
        Vec3f center = (geometry.bounds.lo + geometry.bounds.hi) * 0.5f;
        float radius = 0.5f * length(geometry.bounds.extent());
        if (is_finite(center)) v.scene_center = center;
        if (std::isfinite(radius) && radius > 0.0f) v.scene_radius = radius;
    }

    // Emitters weighted by power; emissive textures are not integrated, only
    // the factor counts, which keeps the table exact for untextured lights.
    // Sorted by triangle so area_light_pdf finds a hit triangle by binary search.
    std::vector<uint32_t> prims(geometry.emissive_triangles.begin(), geometry.emissive_triangles.end());
    std::sort(prims.begin(), prims.end());
    prims.erase(std::unique(prims.begin(), prims.end()), prims.end());
    std::vector<double> power;
    double area_power = 0.0;
    for (uint32_t prim : prims) {
        if (prim >= geometry.triangles.size() || materials.empty()) continue;
        uint32_t id = prim < geometry.material.size() ? geometry.material[prim] : 0;
        const ShadingMaterial& m = materials[id < materials.size() ? id : 0];
        double p = usable(double(geometry.triangles[prim].area()) * double(luminance(m.emission)));
        if (p == 0.0) continue;
        emitter_triangles_.push_back(prim);
        power.push_back(p);
        area_power += p;
    }
    double running = 0.0;
    for (double p : power) {
        running += p;
        emitter_cdf_.push_back(float(running / area_power));
    }
    if (!emitter_cdf_.empty()) emitter_cdf_.back() = 1.0f;
    v.emitters = {emitter_triangles_.data(), emitter_cdf_.data(), uint32_t(emitter_triangles_.size())};

    // Selection entries: analytic lights, the area group, the environment.
    std::vector<double> entry_power;
    for (const Light& light : scene.lights) entry_power.push_back(analytic_light_power(light, v.scene_radius));
    if (v.emitters.count > 0) entry_power.push_back(usable(kPi * area_power));
    if (v.environment.emits()) entry_power.push_back(usable(v.environment.power_proxy(v.scene_radius)));
    double total = 0.0;
    for (double p : entry_power) total += p;
    const bool uniform = !(total > 0.0) || !std::isfinite(total);
    running = 0.0;
    for (size_t i = 0; i < entry_power.size(); ++i) {
        running += uniform ? 1.0 : entry_power[i];
        selection_cdf_.push_back(float(running / (uniform ? double(entry_power.size()) : total)));
    }
    if (!selection_cdf_.empty()) selection_cdf_.back() = 1.0f;
    v.selection_cdf = selection_cdf_.data();
    v.selection_count = uint32_t(selection_cdf_.size());
}

}  // namespace rf
