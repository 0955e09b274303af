// The environment as a light: radiance lookup and importance sampling of an
// equirectangular map by luminance, after Pharr, Jakob, Humphreys, "Physically
// Based Rendering", 3rd ed., §14.2.4: a piecewise-constant 2D distribution
// over the map's (u, v) domain, sampled as a marginal over rows and a
// conditional within the chosen row, each row weighted by sin(theta) so the
// density follows radiance per unit solid angle. A uv density converts to
// solid angle by p(w) = p(u, v) / (2 pi^2 sin(theta)).
//
// Mapping (the same as the path the camera rays take): +y up,
// phi = atan2(dir.x, -dir.z) + rotation, u = 0.5 + phi / (2 pi),
// v = acos(dir.y) / pi; the map repeats in u and clamps in v.
#pragma once

#include <cmath>
#include <cstdint>
#include <vector>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/scene.h"
#include "math/color.h"
#include "render/sampling.h"
#include "render/texture_sampling.h"

namespace rf {

// Index r in [0, n) of the interval cdf[r] <= u < cdf[r + 1] of a cumulative
// table of n + 1 entries (cdf[0] = 0, cdf[n] = 1). The largest such r is
// taken, so intervals of zero width are never returned for u < 1.
RF_HDI int find_cdf_interval(const float* cdf, int n, float u) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {  // largest r with cdf[r] <= u
        int mid = (lo + hi + 1) / 2;
        if (cdf[mid] <= u) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

struct EnvironmentLight {
    Vec3f constant{0};               // radiance (before strength) when there is no map
    TextureView map;                 // invalid view = constant environment; wraps repeat in u, clamp in v
    float strength = 1, rotation_radians = 0;
    const float* marginal_cdf = nullptr;     // height+1 entries
    const float* conditional_cdf = nullptr;  // height * (width+1)
    int width = 0, height = 0;               // of the distribution (may be the map's size or a downsampled one)
    float average_luminance = 0;             // of the map over the sphere, before strength

    [[nodiscard]] RF_HDI bool has_distribution() const {
        return marginal_cdf != nullptr && conditional_cdf != nullptr && width > 0 && height > 0;
    }

    [[nodiscard]] RF_HDI bool emits() const {
        if (!(strength > 0.0f)) return false;
        if (map.valid()) return has_distribution();
        return max_component(constant) > 0.0f;
    }

    // Radiance arriving along unit direction `dir`.
    [[nodiscard]] RF_HDI Vec3f radiance(Vec3f dir) const {
        if (!map.valid()) return constant * strength;
        float phi = atan2f(dir.x, -dir.z) + rotation_radians;
        float u = 0.5f + phi * (0.5f * kInvPi);
        float v = acosf(fmaxf(-1.0f, fminf(1.0f, dir.y))) * kInvPi;
        Vec4f c = sample_texture(map, Vec2f{u, v});
        return Vec3f(c.x, c.y, c.z) * strength;
    }

    // A direction for the random numbers u, its solid-angle density, and the
    // radiance along it. Uniform over the sphere when there is no map (or the
    // map is black); pdf 0 for the measure-zero poles of the map.
    RF_HDI Vec3f sample(Vec2f u, Vec3f& dir, float& pdf_solid_angle) const {
        if (!has_distribution()) {
            float y = 1.0f - 2.0f * u.x;
            float r = sqrtf(fmaxf(0.0f, 1.0f - y * y));
            float phi = 2.0f * kPi * u.y;
            dir = Vec3f(r * cosf(phi), y, r * sinf(phi));
            pdf_solid_angle = 0.25f * kInvPi;
            return radiance(dir);
        }
        const float below_one = 0.99999994f;
        float ur = fminf(fmaxf(u.x, 0.0f), below_one);
        float uc = fminf(fmaxf(u.y, 0.0f), below_one);
        int row = find_cdf_interval(marginal_cdf, height, ur);
        float row_width = marginal_cdf[row + 1] - marginal_cdf[row];
        const float* row_cdf = conditional_cdf + size_t(row) * size_t(width + 1);
        int col = find_cdf_interval(row_cdf, width, uc);
        float col_width = row_cdf[col + 1] - row_cdf[col];
        // Position inside the chosen cell, clamped so float error stays inside it.
        float dv = row_width > 0.0f ? fminf((ur - marginal_cdf[row]) / row_width, below_one) : 0.5f;
        float du = col_width > 0.0f ? fminf((uc - row_cdf[col]) / col_width, below_one) : 0.5f;
        float tex_v = (float(row) + dv) / float(height);
        float tex_u = (float(col) + du) / float(width);

        float theta = tex_v * kPi;
        float sin_theta = sinf(theta);
        float phi = (tex_u - 0.5f) * (2.0f * kPi) - rotation_radians;
        dir = Vec3f(sin_theta * sinf(phi), cosf(theta), -sin_theta * cosf(phi));
        float pdf_uv = row_width * float(height) * col_width * float(width);
        if (!(sin_theta > 0.0f) || !(pdf_uv > 0.0f)) {
            pdf_solid_angle = 0.0f;
            return Vec3f(0.0f);
        }
        pdf_solid_angle = pdf_uv / (2.0f * kPi * kPi * sin_theta);
        // radiance(dir) would map dir back to (tex_u, tex_v); look it up directly.
        Vec4f c = sample_texture(map, Vec2f{tex_u, tex_v});
        return Vec3f(c.x, c.y, c.z) * strength;
    }

    // Solid-angle density with which sample() returns unit direction `dir`.
    [[nodiscard]] RF_HDI float pdf(Vec3f dir) const {
        if (!has_distribution()) return 0.25f * kInvPi;
        float y = fmaxf(-1.0f, fminf(1.0f, dir.y));
        float sin_theta = sqrtf(fmaxf(0.0f, 1.0f - y * y));
        if (!(sin_theta > 0.0f)) return 0.0f;
        float phi = atan2f(dir.x, -dir.z) + rotation_radians;
        float tex_u = 0.5f + phi * (0.5f * kInvPi);
        tex_u -= floorf(tex_u);  // repeat (rotation may push it out of [0, 1))
        float tex_v = acosf(y) * kInvPi;
        int row = int(tex_v * float(height));
        int col = int(tex_u * float(width));
        row = row < 0 ? 0 : (row >= height ? height - 1 : row);
        col = col < 0 ? 0 : (col >= width ? width - 1 : col);
        const float* row_cdf = conditional_cdf + size_t(row) * size_t(width + 1);
        float pdf_uv = (marginal_cdf[row + 1] - marginal_cdf[row]) * float(height) *
                       (row_cdf[col + 1] - row_cdf[col]) * float(width);
        return pdf_uv / (2.0f * kPi * kPi * sin_theta);
    }

    // Rough power for choosing among lights: the flux the environment sends
    // through a disc of the scene's radius, pi r^2 * (average luminance * pi).
    [[nodiscard]] RF_HDI float power_proxy(float scene_radius) const {
        if (!emits()) return 0.0f;
        float average = (map.valid() ? average_luminance : luminance(constant)) * strength;
        return kPi * scene_radius * scene_radius * average * kPi;
    }
};

// Host owner of the distribution's tables; light() views them and the
// scene's texture, so `scene` must outlive both.
class EnvironmentDistribution {
public:
    // Distributions wider than max_width (or taller than max_width / 2) are
    // built on a coarser grid, each cell covering the texels it overlaps.
    explicit EnvironmentDistribution(const Scene& scene, int max_width = 2048);

    [[nodiscard]] EnvironmentLight light() const;

private:
    EnvironmentLight base_;  // without the table pointers
    std::vector<float> marginal_cdf_;
    std::vector<float> conditional_cdf_;
};

}  // namespace rf
