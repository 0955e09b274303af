#include "render/scene_view.h"

#include <cmath>

#include "render/color.h"
#include "render/sampling.h"

namespace rf {

HostSceneView::HostSceneView(const Scene& scene, const SceneGeometry& geometry)
    : scene_(&scene), geometry_(&geometry) {
    materials_.reserve(scene.materials.size() + 1);
    for (const Material& m : scene.materials) materials_.push_back(ShadingMaterial::from(m));
    if (materials_.empty()) materials_.push_back(ShadingMaterial::from(Material{}));

    textures_.reserve(scene.textures.size());
    for (const Texture& t : scene.textures) textures_.push_back(make_texture_view(t));

    // Emitters weighted by power; emissive textures are not integrated, only
    // the factor counts, which keeps the table exact for untextured lights.
    double total = 0.0;
    std::vector<double> power;
    for (uint32_t prim : geometry.emissive_triangles) {
        if (prim >= geometry.triangles.size()) continue;
        uint32_t material_id = prim < geometry.material.size() ? geometry.material[prim] : 0;
        double p = double(geometry.triangles[prim].area()) * double(luminance(material(material_id).emission));
        if (!(p > 0.0) || !std::isfinite(p)) continue;
        emitter_triangles_.push_back(prim);
        power.push_back(p);
        total += p;
    }
    double running = 0.0;
    for (double p : power) {
        running += p;
        emitter_cdf_.push_back(float(running / total));
    }
    if (!emitter_cdf_.empty()) emitter_cdf_.back() = 1.0f;
    emitter_table_ = {emitter_triangles_.data(), emitter_cdf_.data(), uint32_t(emitter_triangles_.size())};

    if (const TextureView* t = texture(scene.environment.texture)) {
        environment_texture_ = *t;
        environment_texture_.wrap_s = TextureWrap::Repeat;      // around the horizon
        environment_texture_.wrap_t = TextureWrap::ClampToEdge; // no bleeding across the poles
    }

    if (!geometry.bounds.is_empty()) {
        float d = length(geometry.bounds.extent());
        if (std::isfinite(d) && d > 0.0f) diagonal_ = d;
    }
    // Large enough to clear float error at the hit point for scenes whose
    // coordinates are about the size of their extent, small against features.
    Vec3f far_corner = geometry.bounds.is_empty() ? Vec3f(0.0f) : max(abs(geometry.bounds.lo), abs(geometry.bounds.hi));
    ray_epsilon_ = std::fmax(1e-4f * diagonal_, 1e-5f * max_component(far_corner));
    if (!(ray_epsilon_ > 0.0f)) ray_epsilon_ = 1e-4f;
}

SurfaceHit HostSceneView::emitter_surface(const AreaLightSample& s) const {
    // surface_at interpolates from the hit's barycentrics; the ray only has to
    // reach the sampled point at t = 1.
    Ray ray;
    ray.org = s.position - s.normal;
    ray.dir = s.normal;
    Hit hit;
    hit.t = 1.0f;
    hit.u = s.b1;
    hit.v = s.b2;
    hit.prim = s.prim;
    return surface(ray, hit);
}

Vec3f HostSceneView::environment(Vec3f dir) const {
    const Environment& env = scene_->environment;
    if (!environment_texture_.valid()) return env.color * env.strength;
    // Equirectangular, +y up: u = 0.5 looks down -z, v = 0 is straight up.
    float phi = std::atan2(dir.x, -dir.z) + env.rotation_radians;
    float u = 0.5f + phi * (0.5f * kInvPi);
    float v = std::acos(std::fmax(-1.0f, std::fmin(1.0f, dir.y))) * kInvPi;
    Vec4f c = sample_texture(environment_texture_, Vec2f{u, v});
    return Vec3f(c.x, c.y, c.z) * env.strength;
}

}  // namespace rf
