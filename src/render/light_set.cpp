// Builds the light-selection tables: emissive triangles by power (area x
// luminance of the emission, textures averaged over the triangle, x2 for
// two-sided emitters), the environment's distribution, and one cdf over
// analytic lights, the area group and the environment.
#include "render/light_set.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"
#include "math/color.h"
#include "render/sampling.h"
#include "render/texture_mip.h"

namespace rf {
namespace {

// Non-negative finite power, 0 otherwise.
double usable(double p) { return std::isfinite(p) && p > 0.0 ? p : 0.0; }

// Texture coordinates of flat triangle `prim` (all zero without uvs, as the
// scene view interpolates them).
void triangle_uvs(const Scene& scene, const SceneGeometry& geometry, uint32_t prim, Vec2f uv[3]) {
    const Mesh& mesh = scene.meshes[scene.instances[geometry.triangle_instance[prim]].mesh];
    const uint32_t* idx = &mesh.indices[3 * size_t(geometry.local_triangle[prim])];
    for (int k = 0; k < 3; ++k) uv[k] = mesh.uvs.empty() ? Vec2f{0.0f, 0.0f} : mesh.uvs[idx[k]];
}

// Mean colour of texture `t` over the triangle of texture coordinates uv[],
// as the renderer reconstructs it: k x k stratified points (centres of
// equal-area cells of the triangle), each a trilinear lookup at the level
// whose texels are about one cell, so that the mip chain averages the texels
// between points instead of skipping them. Footprints under 16 texels get
// >= 16 points per texel on level 0: about the integral of the bilinear
// reconstruction (within 1% on a sharp edge). At most 256 lookups.
Vec3f triangle_texture_mean(const MipTextureView& t, const Vec2f uv[3]) {
    const Vec2f d1 = uv[1] - uv[0], d2 = uv[2] - uv[0];
    const double texels =
        0.5 * std::fabs(double(d1.x) * d2.y - double(d1.y) * d2.x) * t.base().width * t.base().height;
    const int k = std::isfinite(texels) ? std::clamp(int(std::ceil(4.0 * std::sqrt(texels))), 8, 16) : 8;
    const float lod = 0.5f * float(std::log2(texels / double(k * k)));  // <= 0 (or NaN): level 0
    Vec3f sum(0.0f);
    for (int i = 0; i < k; ++i)
        for (int j = 0; j < k; ++j) {
            const Vec2f b = sample_uniform_triangle({(float(i) + 0.5f) / float(k), (float(j) + 0.5f) / float(k)});
            const Vec4f c = sample_texture(t, uv[0] * (1.0f - b.x - b.y) + uv[1] * b.x + uv[2] * b.y, lod);
            sum += Vec3f(c.x, c.y, c.z);
        }
    return sum / float(k * k);
}

}  // namespace

double emitter_power(const Scene& scene, const SceneGeometry& geometry, const ShadingMaterial& m,
                     std::span<const MipTextureView> textures, uint32_t prim) {
    Vec3f emission = m.emission;
    if (m.emission_texture >= 0 && size_t(m.emission_texture) < textures.size()) {
        Vec2f uv[3];
        triangle_uvs(scene, geometry, prim, uv);
        emission = emission * triangle_texture_mean(textures[size_t(m.emission_texture)], uv);
    }
    const double sides = m.two_sided_emission ? 2.0 : 1.0;
    return usable(double(geometry.triangles[prim].area()) * double(luminance(emission)) * sides);
}

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
                           const std::vector<ShadingMaterial>& materials, std::span<const MipTextureView> textures)
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

    // Without the renderer's mip views, single-level views of the scene's textures.
    std::vector<MipTextureView> own_views;
    if (textures.empty() && !scene.textures.empty()) {
        for (const Texture& t : scene.textures) own_views.push_back(make_mip_view(t, nullptr));
        textures = own_views;
    }
    // Emitters weighted by power; a triangle that emits nothing (a black
    // part of its emission texture) is not a light. Sorted by triangle so
    // area_light_pdf finds a hit triangle by binary search.
    std::vector<uint32_t> prims(geometry.emissive_triangles.begin(), geometry.emissive_triangles.end());
    std::sort(prims.begin(), prims.end());
    prims.erase(std::unique(prims.begin(), prims.end()), prims.end());
    std::vector<double> prim_power(prims.size(), 0.0);
    if (!materials.empty())
        parallel::for_range(size_t(0), prims.size(), size_t(256), [&](size_t lo, size_t hi) {
            for (size_t i = lo; i < hi; ++i) {
                const uint32_t prim = prims[i];
                if (prim >= geometry.triangles.size()) continue;
                const uint32_t id = prim < geometry.material.size() ? geometry.material[prim] : 0;
                prim_power[i] = emitter_power(scene, geometry, materials[id < materials.size() ? id : 0], textures, prim);
            }
        });
    std::vector<double> power;
    double area_power = 0.0;
    for (size_t i = 0; i < prims.size(); ++i) {
        if (prim_power[i] == 0.0) continue;
        emitter_triangles_.push_back(prims[i]);
        power.push_back(prim_power[i]);
        area_power += prim_power[i];
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
