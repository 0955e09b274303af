// BSDF of the glTF 2.0 metallic-roughness material (glTF 2.0 specification,
// Appendix B "BRDF implementation") with KHR_materials_transmission,
// KHR_materials_ior and KHR_materials_specular, for the path tracer on both
// backends:
//
//   material   = mix(dielectric, metal, metallic)
//   metal      = GGX reflection, Schlick Fresnel with F0 = base_color
//   dielectric = fresnel_mix(ior, base, GGX reflection)
//   base       = mix(Lambert(base_color), GGX transmission * base_color, transmission)
//
// Lobes, each sampled on its own and combined by one-sample MIS (eval and
// pdf sum over every non-delta lobe, so a non-delta sample's weight is
// exactly eval / pdf):
//   metal       metallic * GGX reflection * Schlick(base_color, wo.h)
//   dielectric  (1 - metallic) * rough dielectric interface (Walter, Marschner,
//               Li, Torrance 2007, "Microfacet Models for Refraction through
//               Rough Surfaces"): reflection weighted by F_R(wo.h) and
//               transmission weighted by transmission * (1 - F(wo.h)) * base_color;
//               h is drawn from the visible normals (Heitz 2018) and
//               reflection / refraction is chosen by that microfacet's Fresnel.
//   diffuse     (1 - metallic)(1 - transmission) Lambert(base_color)
//               * (1 - s F_o(n.wo)) (1 - s F_o(n.wi)).
// With roughness below kSmoothRoughness the metal and dielectric lobes are
// delta lobes (mirror; smooth reflect / refract chosen by exact Fresnel).
//
// Specular layer (KHR_materials_specular, s = specular, c = specular_color):
// the opaque share's reflection is s F_o(wo.h) c and the diffuse base under it
// receives (1 - s F_o(n.wo))(1 - s F_o(n.wi)); s = 0 leaves exactly Lambert
// and no reflection lobe to sample. The clear (transmissive) share keeps the
// exact Fresnel of its IOR: what glass does not reflect it transmits, so
// scaling its reflection would either create light or make glass absorb, and
// glass without a reflection is not a physical interface anyway.
// F_R = (1 - transmission) s F_o c + transmission F(eta).
//
// Energy: each microfacet lobe's VNDF-sampled single-scattering weight is at
// most F * G2 / G1(wo) <= F, and reflection + transmission share one
// microfacet (F + (1 - F) = 1). The diffuse base only receives the light the
// interface lets through on both crossings, which is also reciprocal
// (Kelemen & Szirmay-Kalos 2001 style coupling); light that would re-reflect
// inside the layer is dropped. Single scattering loses the light that
// scatters between microfacets (a white rough conductor or rough glass
// renders visibly dark in a white furnace), so the rough conductor and clear
// dielectric lobes add it back (Turquin 2019, "Practical multiple scattering
// compensation for microfacet models"):
//   conductor  f_ms = f_ss (1 + F0 (1 - E(mu_o)) / E(mu_o)), E the albedo of
//              the GGX lobe with F = 1;
//   clear      reflection and transmission divided by E_glass(mu_o, eta),
//              the albedo of the single-scattering rough dielectric.
// E and E_glass are tables of this file's own single-scattering lobes
// (microfacet_tables.h); the compensation changes eval and the sample
// weights, not the pdf (sampling stays VNDF), and depends on wo only, so
// those two lobes are not reciprocal. A white conductor and clear glass then
// have albedo 1 up to the tables' error; everything else stays <= 1
// (checked over a grid of materials in tests/bsdf_test.cpp).
// BasicBsdf<false> is the uncompensated BSDF the tables integrate.
//
// Transmitted radiance is NOT scaled by 1 / eta^2: every ray that enters a
// closed object also leaves it, so the two factors cancel along the path,
// and without them every lobe's throughput stays <= 1. The consequence is
// that the transmission lobe is not reciprocal (it is the adjoint/importance
// form); the single-scattering reflection part of every material is.
//
// Opaque parts have no inside: their Fresnel (F_o, and the opaque share of
// F_R) always uses the entering relative IOR min(eta, 1/eta), so a back face
// seen through a double-sided opaque surface does not show total internal
// reflection.
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "render/material_eval.h"
#include "render/microfacet.h"
#include "render/microfacet_tables.h"
#include "render/sampling.h"

namespace rf {

// Roughness below which the specular lobes become delta lobes (alpha < 9e-4).
inline constexpr float kSmoothRoughness = 0.03f;
// Directions this close to the shading horizon carry no usable energy.
inline constexpr float kBsdfMinCos = 1e-6f;

struct BsdfSample {
    Vec3f wi;                  // unit, world space
    Vec3f weight;              // f(wo,wi) * |dot(n,wi)| / pdf : the path-throughput multiplier
    float pdf = 0.0f;          // solid-angle density over all non-delta lobes (== pdf(wo, wi));
                               // for a delta lobe: the probability of this discrete choice
                               // (lobe selection times reflect/refract choice)
    bool delta = false;        // chosen from a perfectly smooth (delta) lobe
    bool transmission = false; // wi on the other side of the geometric surface than wo
};

// kMultipleScattering: with the energy compensation (the renderer's Bsdf);
// without it, the single-scattering BSDF the albedo tables are made from.
template <bool kMultipleScattering>
class BasicBsdf {
public:
    // m: material at the point. n: unit shading normal, ng: unit geometric
    // normal, both already flipped to wo's side. eta = IOR on wo's side / IOR
    // on the other side (1/ior entering the object, ior leaving it).
    RF_HD static BasicBsdf make(const MaterialSample& m, Vec3f n, Vec3f ng, float eta) {
        BasicBsdf b;
        b.frame_ = Frame::from_normal(n);
        b.ng_ = ng;
        // Energy conservation needs reflectances <= 1; glTF factors and
        // textures are in [0, 1] anyway.
        b.base_ = min(max(m.base_color, Vec3f(0.0f)), Vec3f(1.0f));
        b.metal_weight_ = saturate(m.metallic);
        b.dielectric_weight_ = 1.0f - b.metal_weight_;
        b.transmission_ = saturate(m.transmission);
        b.specular_ = saturate(m.specular);
        b.specular_tint_ = min(max(m.specular_color, Vec3f(0.0f)), Vec3f(1.0f)) * b.specular_;
        b.eta_ = (eta > 0.0f && is_finite(eta)) ? eta : 1.0f;
        b.eta_opaque_ = b.eta_ > 1.0f ? 1.0f / b.eta_ : b.eta_;
        b.roughness_ = saturate(m.roughness);
        b.alpha_ = ggx_alpha_from_roughness(b.roughness_);
        b.smooth_ = !(m.roughness >= kSmoothRoughness);
        // An index-matched interface does not deflect light: straight
        // transmission is a delta whatever the roughness (the rough
        // refraction half vector is undefined there).
        b.index_matched_ = fabsf(b.eta_ - 1.0f) < 1e-3f;
        return b;
    }
    // The same, with the terms that depend only on wo (local direction, lobe
    // probabilities, Fresnel at n.wo, compensation factors) computed once: a
    // path vertex evaluates its BSDF for the light sample and again for the
    // sampled direction.
    RF_HD static BasicBsdf make(const MaterialSample& m, Vec3f n, Vec3f ng, float eta, Vec3f wo) {
        BasicBsdf b = make(m, n, ng, eta);
        b.cached_wo_ = wo;
        b.cached_valid_ = b.compute_view_terms(wo, b.cached_view_);
        b.cached_ = true;
        return b;
    }

    // f(wo,wi) * |dot(n,wi)| summed over the non-delta lobes.
    RF_HD Vec3f eval(Vec3f wo, Vec3f wi) const {
        float unused;
        return evaluate(wo, wi, unused);
    }

    // Solid-angle density with which sample() draws wi from the non-delta
    // lobes, lobe selection included.
    RF_HD float pdf(Vec3f wo, Vec3f wi) const {
        float density;
        evaluate(wo, wi, density);
        return density;
    }

    // eval() and pdf() together: they share the half vector, the Fresnel
    // terms and the lobe probabilities, and light sampling needs both.
    RF_HD Vec3f evaluate(Vec3f wo, Vec3f wi, float& density) const {
        density = 0.0f;
        ViewTerms v;
        if (!view_terms(wo, v)) return Vec3f(0.0f);
        const Vec3f o = v.o;
        Vec3f i = to_local(wi);
        float geometric_cos = dot(ng_, wi);
        Vec3f f(0.0f);
        if (i.z > kBsdfMinCos && geometric_cos > 0.0f) {
            if (!smooth_) {
                Vec3f h = normalize(o + i);
                float cos_oh = dot(o, h);
                if (cos_oh > 0.0f) {
                    // D G2 / (4 o.z i.z) times the cosine i.z.
                    float d = ggx_d(h, alpha_);
                    float spec = d * ggx_g2(o, i, alpha_) / (4.0f * o.z);
                    // The visible-normal density D_v(h) / (4 o.h) of the reflected direction.
                    float reflect_pdf = ggx_g1(o, alpha_) * d / (4.0f * o.z);
                    if (metal_weight_ > 0.0f)
                        f += schlick_fresnel(base_, cos_oh) * (Vec3f(1.0f) + base_ * v.metal_ms) * (metal_weight_ * spec);
                    density += v.p[kMetal] * reflect_pdf;
                    // (An index-matched interface is a delta lobe: its tiny reflection is sampled there.)
                    if (!index_matched_) {
                        if (dielectric_weight_ > 0.0f) f += reflect_color(cos_oh, v.clear_ms) * (dielectric_weight_ * spec);
                        density += v.p[kDielectric] * reflect_probability(cos_oh) * reflect_pdf;
                    }
                }
            }
            float diffuse = diffuse_weight();
            if (diffuse > 0.0f) {
                float through = (1.0f - v.coat_fresnel_o) * (1.0f - specular_ * opaque_fresnel(i.z));
                f += base_ * (diffuse * through * kInvPi * i.z);
            }
            density += v.p[kDiffuse] * i.z * kInvPi;
        } else if (i.z < -kBsdfMinCos && geometric_cos < 0.0f && rough_transmission()) {
            Vec3f h;
            float jacobian;
            if (transmission_half_vector(o, i, h, jacobian)) {
                float cos_oh = dot(o, h);
                float fresnel = dielectric_fresnel_exact(cos_oh, eta_);
                float d = ggx_d(h, alpha_);
                // D G2 |o.h| |i.h| / (o.z |i.z| (eta o.h + i.h)^2) times |i.z|;
                // `jacobian` is |i.h| / (eta o.h + i.h)^2.
                float t = d * ggx_g2(o, i, alpha_) * cos_oh * jacobian / o.z;
                f += base_ * (dielectric_weight_ * transmission_ * (1.0f - fresnel) * v.clear_ms * t);
                density += v.p[kDielectric] * (1.0f - reflect_probability(cos_oh)) * ggx_vndf_pdf(o, h, alpha_) *
                           jacobian;
            }
        }
        if (!is_finite(density)) density = 0.0f;
        return f;
    }

    // u_lobe picks the lobe (and, rescaled, reflection vs refraction), u the
    // direction. False: absorbed or invalid (out is then unspecified).
    RF_HD bool sample(Vec3f wo, float u_lobe, Vec2f u, BsdfSample& out) const {
        ViewTerms v;
        if (!view_terms(wo, v)) return false;
        const Vec3f o = v.o;
        const float* p = v.p;

        // Pick a lobe; u_lobe is rescaled to [0, 1) within the chosen interval.
        int lobe = -1;
        float cdf = 0.0f;
        for (int k = 0; k < kLobeCount; ++k) {
            if (p[k] <= 0.0f) continue;
            lobe = k;  // also the fallback when rounding leaves u_lobe past the last cdf
            if (u_lobe < cdf + p[k]) break;
            cdf += p[k];
        }
        if (lobe < 0) return false;
        float u_choice = fminf(fmaxf((u_lobe - cdf) / p[lobe], 0.0f), 0.99999994f);

        Vec3f i;
        bool refracted = false;
        if (lobe == kDiffuse) {
            i = sample_cosine_hemisphere(u);
        } else if (lobe == kMetal) {
            if (smooth_) {
                i = Vec3f(-o.x, -o.y, o.z);
                Vec3f weight = schlick_fresnel(base_, o.z) * (metal_weight_ / p[kMetal]);
                return finish_delta(i, weight, p[kMetal], out);
            }
            Vec3f h = ggx_sample_vndf(o, alpha_, u);
            i = reflect_about(o, h);
        } else {  // kDielectric
            bool delta = smooth_ || index_matched_;
            Vec3f h = delta ? Vec3f(0.0f, 0.0f, 1.0f) : ggx_sample_vndf(o, alpha_, u);
            float cos_oh = dot(o, h);
            if (!(cos_oh > 0.0f)) return false;
            float p_reflect = reflect_probability(cos_oh);
            if (u_choice < p_reflect) {
                i = reflect_about(o, h);
                if (delta) {
                    // Delta lobes lose nothing between microfacets: no compensation.
                    float p_delta = p[kDielectric] * p_reflect;
                    return finish_delta(i, reflect_color(cos_oh, 1.0f) * (dielectric_weight_ / p_delta), p_delta, out);
                }
            } else {
                if (!refract_about(o, h, eta_, i)) return false;
                refracted = true;
                if (delta) {
                    float p_refract = p[kDielectric] * (1.0f - p_reflect);
                    float fresnel = dielectric_fresnel_exact(cos_oh, eta_);
                    Vec3f weight = base_ * (dielectric_weight_ * transmission_ * (1.0f - fresnel) / p_refract);
                    return finish_delta(i, weight, p_refract, out);
                }
            }
        }

        // A reflection that ends below the surface (or a refraction above it)
        // is absorbed: pdf() there only holds the other side's lobes, so
        // weighting it by eval / pdf would count that light twice.
        if ((i.z < 0.0f) != refracted) return false;
        out.wi = frame_.to_world(i);
        Vec3f f = evaluate(wo, out.wi, out.pdf);
        if (!(out.pdf > 0.0f)) return false;
        if (!(max_component(f) > 0.0f)) return false;
        out.weight = f / out.pdf;
        out.delta = false;
        out.transmission = dot(ng_, out.wi) < 0.0f;
        return is_finite(out.weight);
    }

    // Every lobe that can be chosen is a delta lobe: light sampling cannot help.
    RF_HD bool is_delta() const {
        if (diffuse_weight() > 0.0f && max_component(base_) > 0.0f) return false;
        if (smooth_) return true;
        // Rough: only an index-matched dielectric without metal stays delta.
        return index_matched_ && metal_weight_ <= 0.0f;
    }

    // Denoiser albedo AOV: the color every lobe is tinted by (diffuse and
    // transmission: base_color; metal: F0 = base_color); white for clear glass.
    RF_HD Vec3f albedo() const { return base_; }

private:
    enum { kMetal = 0, kDielectric = 1, kDiffuse = 2, kLobeCount = 3 };

    // Everything that depends on wo alone.
    struct ViewTerms {
        Vec3f o;                   // wo in the local frame
        float p[kLobeCount];       // lobe selection probabilities
        float coat_fresnel_o;      // s F_o(n.wo), the specular layer's share at n.wo
        float metal_ms = 0.0f;     // (1 - E) / E of the conductor lobe (Turquin); 0: none
        float clear_ms = 1.0f;     // 1 / E_glass of the clear dielectric; 1: none
    };

    RF_HD Vec3f to_local(Vec3f w) const { return {dot(w, frame_.t), dot(w, frame_.b), dot(w, frame_.n)}; }

    // False when wo grazes or is below the shading hemisphere.
    RF_HD bool compute_view_terms(Vec3f wo, ViewTerms& v) const {
        v.o = to_local(wo);
        if (!(v.o.z > kBsdfMinCos)) return false;
        if constexpr (kMultipleScattering) {
            // Delta lobes lose nothing between microfacets.
            if (!smooth_ && metal_weight_ > 0.0f) {
                float e = fmaxf(ggx_albedo(v.o.z, roughness_), 0.05f);
                v.metal_ms = (1.0f - e) / e;
            }
            if (rough_transmission()) v.clear_ms = 1.0f / fmaxf(ggx_dielectric_albedo(v.o.z, roughness_, eta_), 0.05f);
        }
        v.coat_fresnel_o = specular_ * opaque_fresnel(v.o.z);
        return lobe_probabilities(v);
    }
    RF_HD bool view_terms(Vec3f wo, ViewTerms& v) const {
        if (!(cached_ && wo == cached_wo_)) return compute_view_terms(wo, v);
        v = cached_view_;
        return cached_valid_;
    }

    RF_HD float diffuse_weight() const { return dielectric_weight_ * (1.0f - transmission_); }
    RF_HD bool rough_transmission() const {
        return !smooth_ && !index_matched_ && transmission_ > 0.0f && dielectric_weight_ > 0.0f;
    }

    // Fresnel of the opaque parts, always as if entering the denser medium.
    RF_HD float opaque_fresnel(float cos_theta) const { return dielectric_fresnel_exact(cos_theta, eta_opaque_); }
    // Exact Fresnel of the clear share; 0 where there is none.
    RF_HD float clear_fresnel(float cos_oh) const {
        return transmission_ > 0.0f ? dielectric_fresnel_exact(cos_oh, eta_) : 0.0f;
    }
    // Reflectance of the dielectric interface: the specular layer of the
    // opaque share plus the clear share (times its compensation clear_ms).
    RF_HD Vec3f reflect_color(float cos_oh, float clear_ms) const {
        Vec3f opaque = transmission_ < 1.0f ? specular_tint_ * ((1.0f - transmission_) * opaque_fresnel(cos_oh)) : Vec3f(0.0f);
        return opaque + Vec3f(transmission_ * clear_fresnel(cos_oh) * clear_ms);
    }
    // Its channel mean without compensation, for sampling decisions.
    RF_HD float reflect_estimate(float cos_oh) const {
        float opaque = transmission_ < 1.0f ? (1.0f - transmission_) * opaque_fresnel(cos_oh) * mean(specular_tint_) : 0.0f;
        return opaque + transmission_ * clear_fresnel(cos_oh);
    }
    // Within the dielectric lobe: P(reflect) = F_R / (F_R + t (1 - F)), which
    // is the exact Fresnel F for clear glass (t = 1).
    RF_HD float reflect_probability(float cos_oh) const {
        float reflect = reflect_estimate(cos_oh);
        float transmit = transmission_ > 0.0f ? transmission_ * (1.0f - dielectric_fresnel_exact(cos_oh, eta_)) : 0.0f;
        float total = reflect + transmit;
        return total > 0.0f ? reflect / total : 1.0f;
    }
    RF_HD static float mean(Vec3f c) { return (c.x + c.y + c.z) * (1.0f / 3.0f); }

    // Lobe selection probabilities, proportional to each lobe's weight
    // estimated from the Fresnel at n.wo (the compensation approximately:
    // F0 taken as its mean). Every lobe that can contribute anywhere gets a
    // nonzero share (otherwise the estimator is biased): Schlick's F is >= F0
    // but also rises above a black F0 off normal incidence, hence the floor
    // on the metal estimate. A lobe that contributes nothing (specular = 0
    // and no transmission) gets none, so no sample is wasted on it.
    RF_HD bool lobe_probabilities(ViewTerms& v) const {
        float cos_o = v.o.z, mean_base = mean(base_);
        float metal = mean(schlick_fresnel(base_, cos_o)) * (1.0f + mean_base * v.metal_ms);
        v.p[kMetal] = metal_weight_ * fmaxf(metal, 0.02f);
        float opaque = transmission_ < 1.0f ? (1.0f - transmission_) * opaque_fresnel(cos_o) * mean(specular_tint_) : 0.0f;
        float fresnel = clear_fresnel(cos_o);
        float clear = transmission_ * (fresnel + (1.0f - fresnel) * mean_base) * v.clear_ms;
        v.p[kDielectric] = dielectric_weight_ * (opaque + clear);
        v.p[kDiffuse] = diffuse_weight() * (1.0f - v.coat_fresnel_o) * mean_base;
        float total = v.p[kMetal] + v.p[kDielectric] + v.p[kDiffuse];
        if (!(total > 0.0f) || !is_finite(total)) return false;
        for (int k = 0; k < kLobeCount; ++k) v.p[k] /= total;
        return true;
    }

    // Generalised half vector of a refraction (Walter et al. 2007, eq. 16):
    // h ~ eta wo + wi, oriented to the macro normal, and the Jacobian
    // |dh/dwi| = |wi.h| / (eta wo.h + wi.h)^2. False when the pair is not a
    // refraction through a front-facing microfacet.
    RF_HD bool transmission_half_vector(Vec3f o, Vec3f i, Vec3f& h, float& jacobian) const {
        Vec3f sum = o * eta_ + i;
        float len2 = dot(sum, sum);
        if (!(len2 > 1e-12f)) return false;
        h = sum * (1.0f / sqrtf(len2));
        if (h.z < 0.0f) h = -h;
        float cos_oh = dot(o, h), cos_ih = dot(i, h);
        if (!(cos_oh > 0.0f) || !(cos_ih < 0.0f)) return false;
        float denom = eta_ * cos_oh + cos_ih;
        jacobian = -cos_ih / (denom * denom);
        return is_finite(jacobian);
    }

    RF_HD bool finish_delta(Vec3f local_wi, Vec3f weight, float probability, BsdfSample& out) const {
        out.wi = frame_.to_world(local_wi);
        bool through = local_wi.z < 0.0f;
        // The direction must leave on the matching side of the geometric surface.
        float geometric_cos = dot(ng_, out.wi);
        if (through ? !(geometric_cos < 0.0f) : !(geometric_cos > 0.0f)) return false;
        out.weight = weight;
        out.pdf = probability;
        out.delta = true;
        out.transmission = through;
        return is_finite(weight) && max_component(weight) > 0.0f;
    }

    Frame frame_{};
    Vec3f ng_;
    Vec3f base_;
    float metal_weight_ = 0.0f;
    float dielectric_weight_ = 1.0f;
    float transmission_ = 0.0f;
    float specular_ = 1.0f;
    Vec3f specular_tint_{1.0f};  // specular * specular_color
    float eta_ = 1.0f;
    float eta_opaque_ = 1.0f;
    float roughness_ = 1.0f;
    float alpha_ = 1.0f;
    bool smooth_ = false;
    bool index_matched_ = false;
    // View terms for the wo given to make() (see there).
    Vec3f cached_wo_;
    ViewTerms cached_view_{};
    bool cached_ = false, cached_valid_ = false;
};

using Bsdf = BasicBsdf<true>;
using SingleScatteringBsdf = BasicBsdf<false>;

}  // namespace rf
