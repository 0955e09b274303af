// Directional albedo of this renderer's single-scattering GGX lobes,
// integrated by sampling the BSDF itself (compensation off) over a
// deterministic 3D Hammersley set: (k + 1/2) / N picks the lobe / reflect vs
// refract, the radical inverses in bases 2 and 3 the visible normal. Host
// only: tools/make_microfacet_tables.cpp writes microfacet_tables.inc with
// these functions, and tests/bsdf_test.cpp recomputes entries with them so
// the committed table cannot silently go stale.
#pragma once

#include <cmath>

#include "render/bsdf.h"

namespace rf {

inline double radical_inverse(unsigned k, unsigned base) {
    double inverse = 1.0 / base, scale = inverse, result = 0.0;
    for (; k > 0; k /= base, scale *= inverse) result += double(k % base) * scale;
    return result;
}

// Mean sample weight (channel 0) of `m` seen from mu = cos(wo, n), with eta
// as in Bsdf::make. Every lobe counts, delta lobes included.
inline double single_scattering_albedo(const MaterialSample& m, float mu, float eta, int samples) {
    const Vec3f n(0.0f, 0.0f, 1.0f);
    const SingleScatteringBsdf bsdf = SingleScatteringBsdf::make(m, n, n, eta);
    const Vec3f wo(std::sqrt(std::fmax(0.0f, 1.0f - mu * mu)), 0.0f, mu);
    double sum = 0.0;
    for (int k = 0; k < samples; ++k) {
        float u_lobe = float((k + 0.5) / samples);
        Vec2f u{float(radical_inverse(unsigned(k), 2)), float(radical_inverse(unsigned(k), 3))};
        BsdfSample s;
        if (bsdf.sample(wo, u_lobe, u, s)) sum += double(s.weight.x);
    }
    return sum / samples;
}

// E(mu, r): the conductor lobe with F = 1 (white base color, Schlick F0 = 1).
inline double ggx_albedo_estimate(float mu, float roughness, int samples) {
    MaterialSample m;
    m.base_color = Vec3f(1.0f);
    m.metallic = 1.0f;
    m.roughness = roughness;
    return single_scattering_albedo(m, mu, 1.0f, samples);
}

// E_glass(mu, r, eta): clear glass (transmission 1, base 1) of IOR
// max(eta, 1/eta), entered (eta < 1) or left (eta > 1).
inline double ggx_dielectric_albedo_estimate(float mu, float roughness, float eta, int samples) {
    MaterialSample m;
    m.base_color = Vec3f(1.0f);
    m.transmission = 1.0f;
    m.roughness = roughness;
    m.ior = eta > 1.0f ? eta : 1.0f / eta;
    return single_scattering_albedo(m, mu, eta, samples);
}

}  // namespace rf
