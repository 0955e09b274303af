// Phong-era surface parameters (MTL's Kd/Ks/Ns, NFF/AFF's f and fm lines)
// onto the material model, one rule for every format that has them:
// - Ks ~ 0 means no highlight was authored: no specular layer (specular = 0),
//   a pure Lambertian base coloured by Kd.
// - Otherwise the dielectric specular layer takes its strength and colour
//   from Ks: specular = max(Ks) (at most 1), specular_color = Ks / max(Ks).
// - The highlight exponent Ns gives the width: Walter et al. 2007
//   ("Microfacet Models for Refraction", eq. 33) match Blinn-Phong exponent
//   n to Beckmann alpha = sqrt(2 / (n + 2)); GGX has the same core width for
//   the same alpha, and rf's roughness is sqrt(alpha) (glTF: alpha =
//   roughness^2), so roughness = (2 / (n + 2))^(1/4).
// - A strong Ks that dominates Kd on a ray-traced reflection model is a
//   mirror: metallic, coloured by Ks (Schlick's F0 = Ks, which is also
//   MTL's illum 5 "Fresnel reflection" curve).
#pragma once

#include "rayforge/math/vec.h"
#include "rayforge/scene/material.h"

namespace rf::io {

// Below this max(Ks) a file means "no specular".
inline constexpr float kNoSpecularBelow = 1e-4f;

// rf roughness for Blinn-Phong exponent `exponent` (negative counts as 0).
float phong_roughness(float exponent);

// The specular layer for Ks and Ns on a dielectric (see above).
void set_phong_specular(Vec3f ks, float exponent, Material& m);

// Whether Ks is strong enough and dominates Kd, so that a reflecting
// surface is better described as a mirror-like metal.
bool phong_mirror(Vec3f kd, Vec3f ks);

// A metal coloured by Ks with the roughness of Ns.
void set_phong_mirror(Vec3f ks, float exponent, Material& m);

}  // namespace rf::io
