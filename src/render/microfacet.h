// Building blocks of microfacet BSDFs, shared by both backends. All vectors
// are unit and expressed in the local shading frame: z is the macro normal.
//
//   - GGX / Trowbridge-Reitz normal distribution D(h), isotropic
//     (Walter, Marschner, Li, Torrance 2007, "Microfacet Models for
//     Refraction through Rough Surfaces").
//   - Smith masking G1 and height-correlated masking-shadowing G2
//     (Heitz 2014, "Understanding the Masking-Shadowing Function in
//     Microfacet-Based BRDFs", JCGT 3(2)).
//   - Sampling of the distribution of visible normals D_wo(h) and its pdf
//     (Heitz 2018, "Sampling the GGX Distribution of Visible Normals",
//     JCGT 7(4)).
//   - Exact dielectric Fresnel reflectance and Schlick's approximation for
//     conductors (Schlick 1994, "An Inexpensive BRDF Model for
//     Physically-based Rendering").
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "render/sampling.h"

namespace rf {

// Below this alpha float precision of D suffers and the lobe is a mirror in
// all but name; callers switch to a delta lobe well before (see bsdf.h).
inline constexpr float kMinGgxAlpha = 1e-3f;

// glTF: alpha = roughness^2 (perceptually linear roughness).
RF_HDI float ggx_alpha_from_roughness(float roughness) {
    return fmaxf(roughness * roughness, kMinGgxAlpha);
}

// D(h) = alpha^2 / (pi (cos^2(alpha^2 - 1) + 1)^2). With a unit h,
// cos^2 (alpha^2 - 1) + 1 = z^2 alpha^2 + (x^2 + y^2), which keeps full
// precision near the peak where 1 - z^2 would cancel.
RF_HDI float ggx_d(Vec3f h, float alpha) {
    if (h.z <= 0.0f) return 0.0f;
    float a2 = alpha * alpha;
    float denom = h.z * h.z * a2 + (h.x * h.x + h.y * h.y);
    if (!(denom > 0.0f)) return 0.0f;
    return a2 / (kPi * denom * denom);
}

// sqrt(z^2 + alpha^2 (x^2 + y^2)) = |z| sqrt(1 + alpha^2 tan^2): Smith's
// Lambda(w) = (that / |z| - 1) / 2 for GGX.
RF_HDI float ggx_lambda_root(Vec3f w, float alpha) {
    return sqrtf(w.z * w.z + alpha * alpha * (w.x * w.x + w.y * w.y));
}

// Smith masking G1(w) = 1 / (1 + Lambda(w)) = 2|z| / (|z| + root); the side
// test (w.h against w.z) is left to the caller, which knows h.
RF_HDI float ggx_g1(Vec3f w, float alpha) {
    float z = fabsf(w.z);
    float denom = z + ggx_lambda_root(w, alpha);
    return denom > 0.0f ? 2.0f * z / denom : 0.0f;
}

// Height-correlated masking-shadowing G2 = 1 / (1 + Lambda(wo) + Lambda(wi))
// (Heitz 2014, eq. 99), written without divisions by |z|. Also used for
// transmission, as pbrt-v4 and Mitsuba do; it is <= G1(wo), which keeps the
// VNDF-sampled weight G2 / G1(wo) <= 1.
RF_HDI float ggx_g2(Vec3f wo, Vec3f wi, float alpha) {
    float zo = fabsf(wo.z), zi = fabsf(wi.z);
    float denom = zi * ggx_lambda_root(wo, alpha) + zo * ggx_lambda_root(wi, alpha);
    return denom > 0.0f ? 2.0f * zo * zi / denom : 0.0f;
}

// Visible-normal density D_wo(h) = G1(wo) max(0, wo.h) D(h) / wo.z; it
// integrates to 1 over the hemisphere of h for every wo above the surface.
RF_HDI float ggx_vndf_pdf(Vec3f wo, Vec3f h, float alpha) {
    if (wo.z <= 0.0f) return 0.0f;
    float cos_oh = dot(wo, h);
    if (cos_oh <= 0.0f) return 0.0f;
    return ggx_g1(wo, alpha) * cos_oh * ggx_d(h, alpha) / wo.z;
}

// Heitz 2018: stretch wo into the configuration where alpha = 1, sample the
// projected area of the unit hemisphere as seen from there (a disk whose
// lower half is squashed by the projection), lift the point onto the
// hemisphere and unstretch the normal. Requires wo.z > 0; returns h with
// h.z >= 0.
RF_HDI Vec3f ggx_sample_vndf(Vec3f wo, float alpha, Vec2f u) {
    Vec3f v = normalize(Vec3f(alpha * wo.x, alpha * wo.y, wo.z));
    // Basis around v; any tangent when v is the pole.
    float len2 = v.x * v.x + v.y * v.y;
    Vec3f t1 = len2 > 0.0f ? Vec3f(-v.y, v.x, 0.0f) * (1.0f / sqrtf(len2)) : Vec3f(1.0f, 0.0f, 0.0f);
    Vec3f t2 = cross(v, t1);
    // Uniform disk point, then the half disk facing away from v shrinks by
    // (1 + v.z) / 2 so the density follows the projected area.
    float r = sqrtf(u.x);
    float phi = 2.0f * kPi * u.y;
    float p1 = r * cosf(phi);
    float p2 = r * sinf(phi);
    float s = 0.5f * (1.0f + v.z);
    p2 = (1.0f - s) * sqrtf(fmaxf(0.0f, 1.0f - p1 * p1)) + s * p2;
    Vec3f nh = t1 * p1 + t2 * p2 + v * sqrtf(fmaxf(0.0f, 1.0f - p1 * p1 - p2 * p2));
    return normalize(Vec3f(alpha * nh.x, alpha * nh.y, fmaxf(0.0f, nh.z)));
}

// Exact Fresnel reflectance of a smooth dielectric interface for
// unpolarised light. cos_i: cosine on the incident side (clamped to [0, 1]);
// eta = IOR on the incident side / IOR on the other side. 1 under total
// internal reflection, exactly 0 for eta == 1.
RF_HDI float dielectric_fresnel_exact(float cos_i, float eta) {
    cos_i = fminf(fmaxf(cos_i, 0.0f), 1.0f);
    float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return 1.0f;
    float cos_t = sqrtf(1.0f - sin2_t);
    float denom_s = eta * cos_i + cos_t;
    float denom_p = cos_i + eta * cos_t;
    if (!(denom_s > 0.0f) || !(denom_p > 0.0f)) return 1.0f;  // cos_i = 0: grazing
    float rs = (eta * cos_i - cos_t) / denom_s;
    float rp = (cos_i - eta * cos_t) / denom_p;
    return 0.5f * (rs * rs + rp * rp);
}

// Schlick's approximation with a colored normal-incidence reflectance f0,
// the glTF conductor Fresnel.
RF_HDI Vec3f schlick_fresnel(Vec3f f0, float cos_theta) {
    float m = 1.0f - fminf(fmaxf(cos_theta, 0.0f), 1.0f);
    float m2 = m * m;
    float m5 = m2 * m2 * m;
    return f0 + (Vec3f(1.0f) - f0) * m5;
}

// Mirror wo about the unit normal h (both pointing away from the surface).
RF_HDI Vec3f reflect_about(Vec3f wo, Vec3f h) { return h * (2.0f * dot(wo, h)) - wo; }

// Refraction of the direction leaving along -wo through an interface with
// unit normal h on wo's side (wo.h > 0); eta = IOR on wo's side / IOR on the
// other side. False under total internal reflection.
RF_HDI bool refract_about(Vec3f wo, Vec3f h, float eta, Vec3f& wi) {
    float cos_i = dot(wo, h);
    float sin2_t = eta * eta * fmaxf(0.0f, 1.0f - cos_i * cos_i);
    if (sin2_t >= 1.0f) return false;
    float cos_t = sqrtf(1.0f - sin2_t);
    wi = normalize(wo * (-eta) + h * (eta * cos_i - cos_t));
    return true;
}

}  // namespace rf
