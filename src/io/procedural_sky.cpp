// The procedural sky of "builtin:sky": a simple analytic clear-sky model,
// written for testing environment lighting, not for physical accuracy.
//  - Sky (above the horizon): a gradient from a pale horizon to a blue zenith,
//    mixed by elevation^0.45 (the sky whitens quickly near the horizon), plus a
//    warm glow around the sun that falls off as cos^24 of the angle to it.
//  - Ground (below the horizon): a uniform dark brown, blended from half the
//    horizon colour over the first ~3 degrees so the horizon has no hard seam.
//  - Sun: a disk of uniform radiance, kSkySunAngularRadiusDegrees wide; the
//    texels whose centre lies in it (and always the texel containing the sun's
//    centre, so small maps keep a sun). Its radiance is calibrated on the
//    texture itself so that, integrating the map as piecewise constant, the
//    sun's irradiance on a horizontal plane is kSkySunToSkyIrradiance times
//    the rest of the sky's (by luminance).
#include "io/procedural_sky.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "math/color.h"

namespace rf {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr double kPiD = 3.14159265358979323846;

constexpr Vec3f kHorizonColor{0.80f, 0.88f, 1.00f};
constexpr Vec3f kZenithColor{0.18f, 0.36f, 0.85f};
constexpr Vec3f kGlowColor{1.00f, 0.90f, 0.70f};
constexpr Vec3f kGroundColor{0.12f, 0.10f, 0.08f};
constexpr Vec3f kSunColor{1.00f, 0.93f, 0.82f};  // scaled by the calibrated radiance

float radians(float degrees) { return degrees * kPi / 180.0f; }

// Radiance of everything but the sun disk in direction `d`.
Vec3f sky_radiance(Vec3f d, Vec3f sun) {
    if (d.y >= 0.0f) {
        const Vec3f gradient = lerp(kHorizonColor, kZenithColor, std::pow(d.y, 0.45f));
        const float glow = std::pow(std::fmax(dot(d, sun), 0.0f), 24.0f);
        return gradient + kGlowColor * glow;
    }
    const float blend = std::fmin(-d.y / 0.05f, 1.0f);  // sin(3 degrees) ~ 0.05
    return lerp(kHorizonColor * 0.5f, kGroundColor, blend);
}

// Solid angle of a texel of row j, weighted by the cosine to +y and limited to
// the upper hemisphere: the exact integral of max(cos theta, 0) over the texel,
// (2 pi / w) * (c0^2 - c1^2) / 2 with c = max(cos theta, 0) at its top and bottom edges.
double row_cosine_weight(int j, int width, int height) {
    const double c0 = std::fmax(std::cos(kPiD * double(j) / double(height)), 0.0);
    const double c1 = std::fmax(std::cos(kPiD * double(j + 1) / double(height)), 0.0);
    return (2.0 * kPiD / double(width)) * 0.5 * (c0 * c0 - c1 * c1);
}

}  // namespace

Vec3f equirect_direction(float u, float v) {
    const float phi = (u - 0.5f) * 2.0f * kPi;
    const float theta = v * kPi;
    const float s = std::sin(theta);
    return {s * std::sin(phi), std::cos(theta), -s * std::cos(phi)};
}

Vec3f sky_sun_direction(float elevation_deg, float azimuth_deg) {
    const float e = radians(elevation_deg), a = radians(azimuth_deg);
    return {std::cos(e) * std::sin(a), std::sin(e), -std::cos(e) * std::cos(a)};
}

Texture make_sky_texture(int width, int height, float sun_elevation_deg, float sun_azimuth_deg) {
    if (width < 8 || height < 4 || width > 16384 || height > 8192)
        throw Error("builtin:sky: size " + std::to_string(width) + "x" + std::to_string(height) +
                    " is outside 8x4 .. 16384x8192");
    if (!(sun_elevation_deg >= 1.0f && sun_elevation_deg <= 90.0f))
        throw Error("builtin:sky: sun elevation must be in [1, 90] degrees");
    if (!std::isfinite(sun_azimuth_deg)) throw Error("builtin:sky: sun azimuth must be finite");

    const Vec3f sun = sky_sun_direction(sun_elevation_deg, sun_azimuth_deg);
    const float cos_sun_radius = std::cos(radians(kSkySunAngularRadiusDegrees));
    // The texel that contains the sun's centre, by the map's own convention.
    const float sun_u = 0.5f + std::atan2(sun.x, -sun.z) / (2.0f * kPi);
    const float sun_v = std::acos(std::clamp(sun.y, -1.0f, 1.0f)) / kPi;
    const int sun_i = std::clamp(int(sun_u * float(width)), 0, width - 1);
    const int sun_j = std::clamp(int(sun_v * float(height)), 0, height - 1);

    Texture texture;
    texture.name = "builtin:sky";
    texture.width = width;
    texture.height = height;
    texture.channels = 3;
    texture.encoding = TextureEncoding::LinearFloat;
    texture.wrap_s = TextureWrap::Repeat;
    texture.wrap_t = TextureWrap::ClampToEdge;
    texture.texels_f.resize(size_t(width) * size_t(height) * 3);

    // First the sky, accumulating its horizontal-plane irradiance and the sun
    // disk's cosine-weighted solid angle; then the sun texels get their radiance.
    std::vector<bool> is_sun(size_t(width) * size_t(height), false);
    Vec3f sky_irradiance(0.0f);
    double sun_weight = 0.0;
    for (int j = 0; j < height; ++j) {
        const double weight = row_cosine_weight(j, width, height);
        Vec3f row_sum(0.0f);
        for (int i = 0; i < width; ++i) {
            const Vec3f d = equirect_direction((float(i) + 0.5f) / float(width), (float(j) + 0.5f) / float(height));
            const size_t texel = size_t(j) * size_t(width) + size_t(i);
            if (dot(d, sun) >= cos_sun_radius || (i == sun_i && j == sun_j)) {
                is_sun[texel] = true;
                sun_weight += weight;
                continue;
            }
            const Vec3f radiance = sky_radiance(d, sun);
            texture.texels_f[3 * texel + 0] = radiance.x;
            texture.texels_f[3 * texel + 1] = radiance.y;
            texture.texels_f[3 * texel + 2] = radiance.z;
            row_sum += radiance;
        }
        sky_irradiance += row_sum * float(weight);
    }
    // sun_weight > 0: the sun's own texel starts above the horizon (elevation >= 1).
    const float sun_scale =
        kSkySunToSkyIrradiance * luminance(sky_irradiance) / (luminance(kSunColor) * float(sun_weight));
    const Vec3f sun_radiance = kSunColor * sun_scale;
    for (size_t texel = 0; texel < is_sun.size(); ++texel) {
        if (!is_sun[texel]) continue;
        texture.texels_f[3 * texel + 0] = sun_radiance.x;
        texture.texels_f[3 * texel + 1] = sun_radiance.y;
        texture.texels_f[3 * texel + 2] = sun_radiance.z;
    }
    return texture;
}

}  // namespace rf
