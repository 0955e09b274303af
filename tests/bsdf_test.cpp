// The GGX microfacet building blocks (normalisation, visible-normal
// sampling) and the glTF metallic-roughness BSDF: energy conservation,
// estimator consistency (weight = eval / pdf, pdf integrates to the
// non-delta sampling rate), reciprocity, smooth dielectric and mirror
// limits, robustness. Statistical bounds are 5 sigma of the sample variance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "render/bsdf.h"
#include "render/microfacet.h"
#include "render/microfacet_albedo.h"
#include "render/microfacet_tables.h"
#include "math/random.h"

namespace rf {
namespace {

constexpr double kPiD = 3.14159265358979323846;

// Mean and standard error of a stream of values.
struct Stats {
    double sum = 0.0, sum2 = 0.0;
    long n = 0;
    void add(double v) {
        sum += v;
        sum2 += v * v;
        ++n;
    }
    [[nodiscard]] double mean() const { return sum / double(n); }
    [[nodiscard]] double standard_error() const {
        double m = mean();
        double var = fmax(0.0, sum2 / double(n) - m * m);
        return sqrt(var / double(n));
    }
};

// GGX density written independently of microfacet.h (double precision,
// tangent form) so that it can serve as an importance-sampling proposal:
// pdf(h) = D_a(h) cos(theta_h), sampled by tan^2 = a^2 u / (1 - u).
double reference_ggx_d(double cos_theta, double alpha) {
    double c2 = cos_theta * cos_theta;
    double tan2 = (1.0 - c2) / c2;
    double a2 = alpha * alpha;
    double denom = a2 + tan2;
    return a2 / (kPiD * c2 * c2 * denom * denom);
}

Vec3f sample_reference_ggx(double alpha, Vec2f u) {
    double tan2 = alpha * alpha * double(u.x) / (1.0 - double(u.x));
    double cos_theta = 1.0 / sqrt(1.0 + tan2);
    double sin_theta = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
    double phi = 2.0 * kPiD * double(u.y);
    return {float(sin_theta * cos(phi)), float(sin_theta * sin(phi)), float(cos_theta)};
}

Vec3f direction_from_angles(double cos_theta, double phi) {
    double s = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
    return {float(s * cos(phi)), float(s * sin(phi)), float(cos_theta)};
}

Vec3f uniform_sphere(Vec2f u) {
    double z = 1.0 - 2.0 * double(u.x);
    return direction_from_angles(z, 2.0 * kPiD * double(u.y));
}

TEST(MicrofacetGgx, DistributionIsNormalised) {
    // Integral of D(h) (h.n) over the hemisphere is 1. Proposal: GGX with
    // twice the alpha, so the ratio D / proposal is bounded by 4.
    for (float alpha : {1e-3f, 0.01f, 0.1f, 0.5f, 1.0f}) {
        RandomStream rng(1, 0, 7);
        Stats s;
        const double proposal_alpha = 2.0 * double(alpha);
        for (int k = 0; k < 200000; ++k) {
            Vec3f h = sample_reference_ggx(proposal_alpha, rng.next2());
            if (!(h.z > 0.0f)) continue;
            double proposal = reference_ggx_d(h.z, proposal_alpha) * h.z;
            s.add(double(ggx_d(h, alpha)) * h.z / proposal);
        }
        EXPECT_NEAR(s.mean(), 1.0, 5.0 * s.standard_error() + 1e-4) << "alpha " << alpha;
    }
}

TEST(MicrofacetGgx, VisibleNormalPdfIntegratesToOne) {
    // Proposal: half GGX(2 alpha), half uniform hemisphere, which bounds the
    // ratio both at the peak and near the horizon.
    for (float alpha : {0.01f, 0.1f, 0.5f, 1.0f}) {
        for (double cos_o : {1.0, 0.7, 0.3, 0.05}) {
            const Vec3f wo = direction_from_angles(cos_o, 0.4);
            RandomStream rng(2, 0, 11);
            Stats s;
            const double proposal_alpha = 2.0 * double(alpha);
            for (int k = 0; k < 100000; ++k) {
                Vec2f u = rng.next2();
                Vec3f h = rng.next() < 0.5f ? sample_reference_ggx(proposal_alpha, u)
                                            : direction_from_angles(1.0 - double(u.x), 2.0 * kPiD * double(u.y));
                if (!(h.z > 0.0f)) continue;
                double proposal = 0.5 * reference_ggx_d(h.z, proposal_alpha) * h.z + 0.5 / (2.0 * kPiD);
                s.add(double(ggx_vndf_pdf(wo, h, alpha)) / proposal);
            }
            EXPECT_NEAR(s.mean(), 1.0, 5.0 * s.standard_error() + 1e-4) << "alpha " << alpha << " cos " << cos_o;
        }
    }
}

TEST(MicrofacetGgx, VisibleNormalSamplesFollowPdf) {
    // Chi-square test of sampled h against D_wo(h) integrated over bins.
    // Polar bins are uniform in atan(tan(theta) / alpha) so that each one
    // holds a fair share of the lobe.
    constexpr int kThetaBins = 12, kPhiBins = 16, kSub = 24, kSamples = 200000;
    for (float alpha : {0.1f, 0.5f}) {
        for (double cos_o : {0.9, 0.3}) {
            const Vec3f wo = direction_from_angles(cos_o, 1.1);
            auto theta_edge = [&](int k) {
                double v = double(k) / kThetaBins;
                return k == kThetaBins ? kPiD / 2.0 : atan(double(alpha) * tan(v * kPiD / 2.0));
            };
            auto phi_edge = [&](int k) { return 2.0 * kPiD * double(k) / kPhiBins; };
            std::vector<double> expected(kThetaBins * kPhiBins, 0.0);
            double total = 0.0;
            for (int bt = 0; bt < kThetaBins; ++bt) {
                double t0 = theta_edge(bt), t1 = theta_edge(bt + 1);
                for (int bp = 0; bp < kPhiBins; ++bp) {
                    double p0 = phi_edge(bp), p1 = phi_edge(bp + 1);
                    double sum = 0.0;
                    for (int i = 0; i < kSub; ++i) {
                        double theta = t0 + (t1 - t0) * (i + 0.5) / kSub;
                        for (int j = 0; j < kSub; ++j) {
                            double phi = p0 + (p1 - p0) * (j + 0.5) / kSub;
                            Vec3f h = direction_from_angles(cos(theta), phi);
                            sum += double(ggx_vndf_pdf(wo, h, alpha)) * sin(theta);
                        }
                    }
                    double integral = sum * (t1 - t0) * (p1 - p0) / double(kSub * kSub);
                    expected[bt * kPhiBins + bp] = integral;
                    total += integral;
                }
            }
            EXPECT_NEAR(total, 1.0, 2e-3) << "quadrature of D_wo, alpha " << alpha << " cos " << cos_o;

            std::vector<long> observed(kThetaBins * kPhiBins, 0);
            RandomStream rng(3, 0, 5);
            for (int k = 0; k < kSamples; ++k) {
                Vec3f h = ggx_sample_vndf(wo, alpha, rng.next2());
                ASSERT_NEAR(length(h), 1.0f, 1e-4f);
                ASSERT_GE(h.z, 0.0f);
                double theta = acos(fmin(1.0, fmax(0.0, double(h.z))));
                double v = atan(tan(theta) / double(alpha)) / (kPiD / 2.0);
                int bt = std::min(kThetaBins - 1, int(v * kThetaBins));
                double phi = atan2(double(h.y), double(h.x));
                if (phi < 0.0) phi += 2.0 * kPiD;
                int bp = std::min(kPhiBins - 1, int(phi / (2.0 * kPiD) * kPhiBins));
                ++observed[bt * kPhiBins + bp];
            }
            // Bins expecting fewer than 5 samples are pooled into one.
            double chi2 = 0.0, pooled_expected = 0.0;
            long pooled_observed = 0;
            int used = 0;
            for (size_t b = 0; b < expected.size(); ++b) {
                double e = expected[b] * kSamples;
                if (e < 5.0) {
                    pooled_expected += e;
                    pooled_observed += observed[b];
                    continue;
                }
                chi2 += (observed[b] - e) * (observed[b] - e) / e;
                ++used;
            }
            if (pooled_expected >= 5.0) {
                chi2 += (pooled_observed - pooled_expected) * (pooled_observed - pooled_expected) / pooled_expected;
                ++used;
            }
            double dof = used - 1;
            EXPECT_LT(chi2, dof + 5.0 * sqrt(2.0 * dof)) << "alpha " << alpha << " cos " << cos_o;
        }
    }
}

TEST(MicrofacetFresnel, ExactAndSchlickLimits) {
    for (float ior : {1.1f, 1.5f, 2.4f}) {
        double f0 = (ior - 1.0) * (ior - 1.0) / ((ior + 1.0) * (ior + 1.0));
        EXPECT_NEAR(dielectric_fresnel_exact(1.0f, 1.0f / ior), f0, 1e-6);
        EXPECT_NEAR(dielectric_fresnel_exact(1.0f, ior), f0, 1e-6);
        EXPECT_FLOAT_EQ(dielectric_fresnel_exact(0.0f, 1.0f / ior), 1.0f);
        // Beyond the critical angle from inside: total internal reflection.
        float sin_critical = 1.0f / ior;
        float cos_beyond = sqrtf(1.0f - fminf(1.0f, sin_critical * 1.01f) * fminf(1.0f, sin_critical * 1.01f));
        EXPECT_FLOAT_EQ(dielectric_fresnel_exact(cos_beyond, ior), 1.0f);
    }
    EXPECT_EQ(dielectric_fresnel_exact(0.6f, 1.0f), 0.0f);
    // Brewster's angle: the p-polarised part vanishes.
    double brewster = atan(1.5);
    double cos_t = sqrt(1.0 - pow(sin(brewster) / 1.5, 2));
    double rs = (cos(brewster) - 1.5 * cos_t) / (cos(brewster) + 1.5 * cos_t);
    EXPECT_NEAR(dielectric_fresnel_exact(float(cos(brewster)), 1.0f / 1.5f), 0.5 * rs * rs, 1e-5);

    Vec3f f0(0.9f, 0.5f, 0.1f);
    Vec3f normal = schlick_fresnel(f0, 1.0f);
    EXPECT_FLOAT_EQ(normal.x, 0.9f);
    EXPECT_FLOAT_EQ(normal.z, 0.1f);
    Vec3f grazing = schlick_fresnel(f0, 0.0f);
    EXPECT_FLOAT_EQ(grazing.y, 1.0f);
}

// --- BSDF ------------------------------------------------------------------

MaterialSample material(float metallic, float roughness, float transmission, float ior,
                        Vec3f base = Vec3f(1.0f), float specular = 1.0f, Vec3f specular_color = Vec3f(1.0f)) {
    MaterialSample m;
    m.base_color = base;
    m.metallic = metallic;
    m.roughness = roughness;
    m.transmission = transmission;
    m.ior = ior;
    m.specular = specular;
    m.specular_color = specular_color;
    return m;
}

// KHR_materials_specular settings the grids run through: default, a tinted
// half-strength layer, none.
struct SpecularLayer {
    float specular;
    Vec3f color;
};
const SpecularLayer kSpecularLayers[] = {{1.0f, Vec3f(1.0f)}, {0.5f, Vec3f(1.0f, 0.5f, 0.2f)}, {0.0f, Vec3f(1.0f)}};

// Error allowed on top of the noise where the compensation makes an albedo
// exactly 1 in theory: the tables' integration and interpolation error.
constexpr double kTableTolerance = 3e-3;

// A tilted shading frame, to exercise the world <-> local transforms.
const Vec3f kNormal = normalize(Vec3f(0.3f, -0.5f, 0.8f));

Vec3f world_direction(Vec3f n, double cos_theta, double phi) {
    return Frame::from_normal(n).to_world(direction_from_angles(cos_theta, phi));
}

struct AlbedoEstimate {
    Stats channel[3];
    long delta = 0, non_delta = 0;
};

template <class B>
AlbedoEstimate estimate_albedo(const B& bsdf, Vec3f wo, int samples, uint32_t seed) {
    AlbedoEstimate a;
    RandomStream rng(seed, 0, 99);
    for (int k = 0; k < samples; ++k) {
        BsdfSample s;
        float u_lobe = rng.next();
        Vec2f u = rng.next2();
        Vec3f w(0.0f);
        if (bsdf.sample(wo, u_lobe, u, s)) {
            w = s.weight;
            ++(s.delta ? a.delta : a.non_delta);
        }
        for (int c = 0; c < 3; ++c) a.channel[c].add(w[c]);
    }
    return a;
}

class BsdfAlbedo : public ::testing::TestWithParam<float> {};

TEST_P(BsdfAlbedo, NeverExceedsOne) {
    const float metallic = GetParam();
    constexpr int kSamples = 5000;
    uint32_t seed = 0;
    for (const SpecularLayer& layer : kSpecularLayers)
    for (float roughness : {0.0f, 0.05f, 0.3f, 0.7f, 1.0f})
        for (float transmission : {0.0f, 0.5f, 1.0f})
            for (float ior : {1.1f, 1.5f, 2.4f})
                for (bool entering : {true, false}) {
                    Bsdf bsdf = Bsdf::make(
                        material(metallic, roughness, transmission, ior, Vec3f(1.0f), layer.specular, layer.color),
                        kNormal, kNormal, entering ? 1.0f / ior : ior);
                    for (double cos_o : {1.0, 0.7, 0.3, 0.05}) {
                        Vec3f wo = world_direction(kNormal, cos_o, 0.7);
                        AlbedoEstimate a = estimate_albedo(bsdf, wo, kSamples, ++seed);
                        for (int c = 0; c < 3; ++c) {
                            EXPECT_LE(a.channel[c].mean(),
                                      1.0 + 5.0 * a.channel[c].standard_error() + kTableTolerance)
                                << "metallic " << metallic << " roughness " << roughness << " transmission "
                                << transmission << " ior " << ior << (entering ? " entering" : " leaving")
                                << " cos " << cos_o << " specular " << layer.specular;
                        }
                    }
                }
}

INSTANTIATE_TEST_SUITE_P(BsdfMetallic, BsdfAlbedo, ::testing::Values(0.0f, 0.5f, 1.0f));

TEST(Bsdf, WhiteLambertReflectsEverything) {
    // ior 1: no specular reflection at all, so the diffuse lobe sees no
    // Fresnel loss and a white base reflects all light.
    Bsdf bsdf = Bsdf::make(material(0.0f, 1.0f, 0.0f, 1.0f), kNormal, kNormal, 1.0f);
    for (double cos_o : {1.0, 0.7, 0.3, 0.05}) {
        AlbedoEstimate a = estimate_albedo(bsdf, world_direction(kNormal, cos_o, 2.0), 20000, 5);
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(a.channel[c].mean(), 1.0, 5.0 * a.channel[c].standard_error() + 1e-5) << "cos " << cos_o;
    }
}

TEST(Bsdf, WeightIsEvalOverPdf) {
    RandomStream rng(6, 0, 1);
    long checked = 0;
    for (const SpecularLayer& layer : kSpecularLayers)
    for (float metallic : {0.0f, 0.5f, 1.0f})
        for (float roughness : {0.0f, 0.05f, 0.3f, 1.0f})
            for (float transmission : {0.0f, 0.5f, 1.0f})
                for (float eta : {1.0f / 1.5f, 1.5f}) {
                    Bsdf bsdf = Bsdf::make(material(metallic, roughness, transmission, 1.5f, Vec3f(0.8f, 0.5f, 0.3f),
                                                    layer.specular, layer.color),
                                           kNormal, kNormal, eta);
                    for (int k = 0; k < 100; ++k) {
                        Vec3f wo = world_direction(kNormal, 0.02 + 0.98 * rng.next(), 2.0 * kPiD * rng.next());
                        BsdfSample s;
                        float u_lobe = rng.next();
                        if (!bsdf.sample(wo, u_lobe, rng.next2(), s)) continue;
                        EXPECT_NEAR(length(s.wi), 1.0f, 1e-4f);
                        EXPECT_EQ(s.transmission, dot(kNormal, s.wi) < 0.0f);
                        if (s.delta) continue;
                        float pdf = bsdf.pdf(wo, s.wi);
                        Vec3f f = bsdf.eval(wo, s.wi);
                        ASSERT_GT(pdf, 0.0f);
                        EXPECT_NEAR(pdf, s.pdf, 1e-4f * s.pdf);
                        for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.weight[c], f[c] / pdf, 1e-4f * f[c] / pdf + 1e-12f);
                        ++checked;
                    }
                }
    EXPECT_GT(checked, 10000);
}

TEST(Bsdf, PdfIntegratesToNonDeltaSampleRate) {
    // Integral of pdf over the sphere (uniform sampling) against the
    // fraction of sample() calls that return a non-delta direction: both
    // count the lobes' mass that lands on the valid side of the surface.
    struct Case {
        float metallic, roughness, transmission, eta, specular = 1.0f;
    };
    const Case cases[] = {{0.0f, 1.0f, 0.0f, 1.0f / 1.5f}, {0.0f, 0.5f, 0.0f, 1.0f / 2.4f}, {1.0f, 0.5f, 0.0f, 1.0f},
                          {0.5f, 0.5f, 1.0f, 1.0f / 1.5f}, {0.0f, 0.5f, 1.0f, 1.5f},        {0.0f, 1.0f, 0.5f, 1.0f / 1.5f},
                          {0.0f, 0.0f, 0.0f, 1.0f / 1.5f}, {0.3f, 0.0f, 0.5f, 1.0f / 1.5f},
                          {0.0f, 0.4f, 0.0f, 1.0f / 1.5f, 0.5f}, {0.0f, 0.4f, 0.0f, 1.0f / 1.5f, 0.0f},
                          {0.5f, 0.3f, 0.5f, 1.5f, 0.0f}};
    constexpr int kSamples = 60000;
    uint32_t seed = 0;
    for (const Case& c : cases)
        for (double cos_o : {0.9, 0.4}) {
            Bsdf bsdf = Bsdf::make(
                material(c.metallic, c.roughness, c.transmission, 1.5f, Vec3f(1.0f), c.specular, Vec3f(0.9f, 0.6f, 0.3f)),
                kNormal, kNormal, c.eta);
            Vec3f wo = world_direction(kNormal, cos_o, 0.3);
            RandomStream rng(++seed, 0, 17);
            Stats integral, rate;
            for (int k = 0; k < kSamples; ++k) {
                Vec3f w = uniform_sphere(rng.next2());
                integral.add(4.0 * kPiD * double(bsdf.pdf(wo, w)));
                BsdfSample s;
                float u_lobe = rng.next();
                bool ok = bsdf.sample(wo, u_lobe, rng.next2(), s);
                rate.add(ok && !s.delta ? 1.0 : 0.0);
            }
            double sigma = sqrt(integral.standard_error() * integral.standard_error() +
                                rate.standard_error() * rate.standard_error());
            EXPECT_NEAR(integral.mean(), rate.mean(), 5.0 * sigma + 1e-4)
                << "metallic " << c.metallic << " roughness " << c.roughness << " transmission " << c.transmission
                << " eta " << c.eta << " cos " << cos_o;
            EXPECT_GT(rate.mean(), 0.0);
        }
}

// eval includes |n.wi|, so compare f = eval / |n.wi| both ways.
template <class B>
long check_reciprocity(const B& bsdf, RandomStream& rng, int pairs) {
    long checked = 0;
    for (int k = 0; k < pairs; ++k) {
        double cos_o = 0.02 + 0.98 * rng.next(), cos_i = 0.02 + 0.98 * rng.next();
        Vec3f wo = world_direction(kNormal, cos_o, 2.0 * kPiD * rng.next());
        Vec3f wi = world_direction(kNormal, cos_i, 2.0 * kPiD * rng.next());
        Vec3f forward = bsdf.eval(wo, wi) / dot(kNormal, wi);
        Vec3f backward = bsdf.eval(wi, wo) / dot(kNormal, wo);
        for (int c = 0; c < 3; ++c) {
            float scale = fmaxf(fabsf(forward[c]), fabsf(backward[c]));
            if (scale < 1e-6f) continue;
            EXPECT_NEAR(forward[c], backward[c], 1e-3f * scale);
            ++checked;
        }
    }
    return checked;
}

TEST(Bsdf, ReflectionIsReciprocal) {
    // Holds for every single-scattering reflection lobe and for the specular
    // layer over the diffuse base with the compensation on; the transmission
    // lobe is deliberately not reciprocal (no 1/eta^2 factor), and Turquin's
    // compensation of the conductor and clear lobes depends on wo only, see bsdf.h.
    RandomStream rng(8, 0, 3);
    long checked = 0;
    for (const SpecularLayer& layer : kSpecularLayers)
        for (float roughness : {0.05f, 0.3f, 1.0f})
            for (float eta : {1.0f / 1.5f, 2.4f}) {
                MaterialSample m = material(0.0f, roughness, 0.0f, 1.5f, Vec3f(0.9f, 0.6f, 0.2f), layer.specular, layer.color);
                checked += check_reciprocity(Bsdf::make(m, kNormal, kNormal, eta), rng, 200);
            }
    EXPECT_GT(checked, 5000);
    checked = 0;
    for (float metallic : {0.0f, 0.5f, 1.0f})
        for (float roughness : {0.05f, 0.3f, 1.0f})
            for (float transmission : {0.0f, 0.5f})
                for (float eta : {1.0f / 1.5f, 2.4f}) {
                    MaterialSample m = material(metallic, roughness, transmission, 1.5f, Vec3f(0.9f, 0.6f, 0.2f), 0.7f,
                                                Vec3f(0.5f, 1.0f, 0.8f));
                    checked += check_reciprocity(SingleScatteringBsdf::make(m, kNormal, kNormal, eta), rng, 400);
                }
    EXPECT_GT(checked, 10000);
}


double reference_fresnel(double cos_i, double eta) {
    double sin2_t = eta * eta * (1.0 - cos_i * cos_i);
    if (sin2_t >= 1.0) return 1.0;
    double cos_t = sqrt(1.0 - sin2_t);
    double rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    double rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

TEST(Bsdf, SmoothGlassReflectsWithFresnelProbability) {
    const float ior = 1.5f;
    const Vec3f tint(0.9f, 0.8f, 0.7f);
    for (bool entering : {true, false})
        for (double cos_o : {1.0, 0.8, 0.3}) {
            const float eta = entering ? 1.0f / ior : ior;
            Bsdf bsdf = Bsdf::make(material(0.0f, 0.0f, 1.0f, ior, tint), kNormal, kNormal, eta);
            EXPECT_TRUE(bsdf.is_delta());
            Vec3f wo = world_direction(kNormal, cos_o, 0.5);
            const double fresnel = reference_fresnel(cos_o, eta);
            constexpr int kSamples = 50000;
            RandomStream rng(9, 0, 1);
            long reflected = 0;
            for (int k = 0; k < kSamples; ++k) {
                BsdfSample s;
                float u_lobe = rng.next();
                if (!bsdf.sample(wo, u_lobe, rng.next2(), s)) continue;
                ASSERT_TRUE(s.delta);
                EXPECT_EQ(bsdf.eval(wo, s.wi), Vec3f(0.0f));
                EXPECT_EQ(bsdf.pdf(wo, s.wi), 0.0f);
                if (!s.transmission) {
                    ++reflected;
                    EXPECT_NEAR(s.weight.x, 1.0f, 1e-4f);
                    EXPECT_NEAR(s.pdf, fresnel, 1e-4);
                } else {
                    EXPECT_NEAR(s.weight.x, tint.x, 1e-4f);
                    EXPECT_NEAR(s.weight.z, tint.z, 1e-4f);
                    EXPECT_NEAR(s.pdf, 1.0 - fresnel, 1e-4);
                }
            }
            double rate = double(reflected) / kSamples;
            double sigma = sqrt(fresnel * (1.0 - fresnel) / kSamples);
            EXPECT_NEAR(rate, fresnel, 5.0 * sigma + 1e-6) << (entering ? "entering" : "leaving") << " cos " << cos_o;
        }
}

TEST(Bsdf, SmoothGlassRefractsBySnellsLaw) {
    const float ior = 1.5f;
    for (bool entering : {true, false})
        for (double cos_o : {1.0, 0.9, 0.6, 0.3}) {
            const float eta = entering ? 1.0f / ior : ior;
            double sin_o = sqrt(1.0 - cos_o * cos_o);
            if (eta * sin_o >= 1.0) continue;  // total internal reflection
            Bsdf bsdf = Bsdf::make(material(0.0f, 0.0f, 1.0f, ior), kNormal, kNormal, eta);
            const double phi = 1.3;
            Vec3f wo = world_direction(kNormal, cos_o, phi);
            // Refracted: same plane, opposite tangential direction, eta sin_o = sin_t.
            double sin_t = eta * sin_o;
            Vec3f expected = Frame::from_normal(kNormal).to_world(
                Vec3f(float(-sin_t * cos(phi)), float(-sin_t * sin(phi)), float(-sqrt(1.0 - sin_t * sin_t))));
            BsdfSample s;
            ASSERT_TRUE(bsdf.sample(wo, 0.999f, Vec2f{0.5f, 0.5f}, s));  // u_lobe past the Fresnel share
            ASSERT_TRUE(s.transmission);
            EXPECT_NEAR(s.wi.x, expected.x, 1e-5f);
            EXPECT_NEAR(s.wi.y, expected.y, 1e-5f);
            EXPECT_NEAR(s.wi.z, expected.z, 1e-5f);
            ASSERT_TRUE(bsdf.sample(wo, 0.0f, Vec2f{0.5f, 0.5f}, s));
            ASSERT_FALSE(s.transmission);
            Vec3f mirror = reflect(-wo, kNormal);
            EXPECT_NEAR(s.wi.x, mirror.x, 1e-5f);
            EXPECT_NEAR(s.wi.z, mirror.z, 1e-5f);
        }
}

TEST(Bsdf, SmoothGlassTotalInternalReflection) {
    const float ior = 1.5f;
    Bsdf bsdf = Bsdf::make(material(0.0f, 0.0f, 1.0f, ior), kNormal, kNormal, ior);  // leaving the glass
    double critical_sin = 1.0 / ior;
    for (double sin_o : {critical_sin * 1.001, 0.8, 0.99}) {
        Vec3f wo = world_direction(kNormal, sqrt(1.0 - sin_o * sin_o), 0.2);
        RandomStream rng(10, 0, 1);
        for (int k = 0; k < 1000; ++k) {
            BsdfSample s;
            float u_lobe = rng.next();
            ASSERT_TRUE(bsdf.sample(wo, u_lobe, rng.next2(), s));
            EXPECT_TRUE(s.delta);
            EXPECT_FALSE(s.transmission);
            EXPECT_NEAR(s.weight.x, 1.0f, 1e-5f);
            EXPECT_NEAR(s.pdf, 1.0f, 1e-5f);
        }
    }
}

TEST(Bsdf, SmoothMetalIsMirrorTintedByBaseColor) {
    const Vec3f base(0.9f, 0.5f, 0.2f);
    Bsdf bsdf = Bsdf::make(material(1.0f, 0.0f, 0.0f, 1.5f, base), kNormal, kNormal, 1.0f / 1.5f);
    EXPECT_TRUE(bsdf.is_delta());
    BsdfSample s;
    ASSERT_TRUE(bsdf.sample(kNormal, 0.3f, Vec2f{0.2f, 0.7f}, s));
    EXPECT_TRUE(s.delta);
    EXPECT_FALSE(s.transmission);
    EXPECT_NEAR(s.wi.x, kNormal.x, 1e-6f);
    EXPECT_NEAR(s.wi.z, kNormal.z, 1e-6f);
    EXPECT_NEAR(s.weight.x, base.x, 1e-6f);
    EXPECT_NEAR(s.weight.y, base.y, 1e-6f);
    EXPECT_NEAR(s.weight.z, base.z, 1e-6f);
    EXPECT_NEAR(s.pdf, 1.0f, 1e-6f);
    // Off normal incidence the mirror is still exact, Schlick brightens it.
    Vec3f wo = world_direction(kNormal, 0.5, 0.9);
    ASSERT_TRUE(bsdf.sample(wo, 0.3f, Vec2f{0.2f, 0.7f}, s));
    Vec3f mirror = reflect(-wo, kNormal);
    EXPECT_NEAR(s.wi.y, mirror.y, 1e-5f);
    Vec3f schlick = schlick_fresnel(base, 0.5f);
    EXPECT_NEAR(s.weight.z, schlick.z, 1e-5f);
    EXPECT_EQ(bsdf.albedo(), base);
}

TEST(Bsdf, DeltaClassification) {
    Vec3f n = kNormal;
    EXPECT_TRUE(Bsdf::make(material(0.0f, 0.0f, 1.0f, 1.5f), n, n, 1.0f / 1.5f).is_delta());
    EXPECT_TRUE(Bsdf::make(material(1.0f, 0.01f, 0.0f, 1.5f), n, n, 1.0f / 1.5f).is_delta());
    EXPECT_FALSE(Bsdf::make(material(0.0f, 0.0f, 0.0f, 1.5f), n, n, 1.0f / 1.5f).is_delta());  // diffuse base
    EXPECT_FALSE(Bsdf::make(material(1.0f, 0.3f, 0.0f, 1.5f), n, n, 1.0f / 1.5f).is_delta());
    EXPECT_FALSE(Bsdf::make(material(0.0f, 0.3f, 1.0f, 1.5f), n, n, 1.0f / 1.5f).is_delta());
    // Index-matched clear material: light passes straight through.
    Bsdf matched = Bsdf::make(material(0.0f, 0.5f, 1.0f, 1.0f), n, n, 1.0f);
    EXPECT_TRUE(matched.is_delta());
    Vec3f wo = world_direction(n, 0.6, 0.1);
    BsdfSample s;
    ASSERT_TRUE(matched.sample(wo, 0.5f, Vec2f{0.3f, 0.3f}, s));
    EXPECT_TRUE(s.transmission);
    EXPECT_NEAR(s.wi.x, -wo.x, 1e-5f);
    EXPECT_NEAR(s.wi.z, -wo.z, 1e-5f);
    EXPECT_NEAR(s.weight.y, 1.0f, 1e-5f);
}

TEST(Bsdf, SidesFollowTheGeometricNormal) {
    // Shading normal tilted away from the geometric one: directions above
    // the shading hemisphere but below the surface reflect nothing, and
    // transmission never goes above the surface.
    const Vec3f ng(0.0f, 0.0f, 1.0f);
    const Vec3f n = normalize(Vec3f(0.6f, 0.0f, 0.8f));
    Bsdf opaque = Bsdf::make(material(0.0f, 0.5f, 0.0f, 1.5f), n, ng, 1.0f / 1.5f);
    Bsdf glass = Bsdf::make(material(0.0f, 0.5f, 1.0f, 1.5f), n, ng, 1.0f / 1.5f);
    Vec3f wo = normalize(Vec3f(-0.2f, 0.1f, 0.9f));
    Vec3f below_surface = normalize(Vec3f(0.9f, 0.0f, -0.1f));  // n.w > 0, ng.w < 0
    ASSERT_GT(dot(n, below_surface), 0.0f);
    EXPECT_EQ(opaque.eval(wo, below_surface), Vec3f(0.0f));
    EXPECT_EQ(opaque.pdf(wo, below_surface), 0.0f);
    Vec3f above_surface = normalize(Vec3f(-0.9f, 0.0f, 0.1f));  // n.w < 0, ng.w > 0
    ASSERT_LT(dot(n, above_surface), 0.0f);
    EXPECT_EQ(glass.eval(wo, above_surface), Vec3f(0.0f));
    EXPECT_EQ(glass.pdf(wo, above_surface), 0.0f);
    RandomStream rng(12, 0, 1);
    for (int k = 0; k < 20000; ++k) {
        BsdfSample s;
        float u_lobe = rng.next();
        Vec2f u = rng.next2();
        for (const Bsdf* b : {&opaque, &glass}) {
            if (!b->sample(wo, u_lobe, u, s)) continue;
            EXPECT_EQ(s.transmission, dot(ng, s.wi) < 0.0f);
            EXPECT_EQ(s.transmission, dot(n, s.wi) < 0.0f);
        }
    }
    // wo below the shading hemisphere: nothing, never NaN.
    Vec3f wo_below = normalize(Vec3f(-0.9f, 0.0f, 0.2f));
    ASSERT_LT(dot(n, wo_below), 0.0f);
    BsdfSample s;
    EXPECT_FALSE(opaque.sample(wo_below, 0.5f, Vec2f{0.5f, 0.5f}, s));
    EXPECT_EQ(opaque.eval(wo_below, n), Vec3f(0.0f));
    EXPECT_EQ(opaque.pdf(wo_below, n), 0.0f);
}

TEST(BsdfSpecular, ZeroSpecularIsExactlyLambert) {
    // No reflection lobe at all: f = base / pi, pdf = cos / pi, weight = base.
    const Vec3f base(0.8f, 0.5f, 0.3f);
    RandomStream rng(14, 0, 1);
    for (float roughness : {0.0f, 0.3f, 1.0f})
        for (float eta : {1.0f / 1.5f, 2.4f}) {
            Bsdf bsdf = Bsdf::make(material(0.0f, roughness, 0.0f, 1.5f, base, 0.0f), kNormal, kNormal, eta);
            EXPECT_FALSE(bsdf.is_delta());
            for (int k = 0; k < 2000; ++k) {
                Vec3f wo = world_direction(kNormal, 0.02 + 0.98 * rng.next(), 2.0 * kPiD * rng.next());
                Vec3f wi = world_direction(kNormal, 0.02 + 0.98 * rng.next(), 2.0 * kPiD * rng.next());
                float cos_i = dot(kNormal, wi);
                Vec3f f = bsdf.eval(wo, wi);
                for (int c = 0; c < 3; ++c) EXPECT_NEAR(f[c], base[c] * kInvPi * cos_i, 1e-6f * f[c]);
                EXPECT_NEAR(bsdf.pdf(wo, wi), kInvPi * cos_i, 1e-6f * cos_i);
                BsdfSample s;
                float u_lobe = rng.next();
                ASSERT_TRUE(bsdf.sample(wo, u_lobe, rng.next2(), s));
                EXPECT_FALSE(s.delta);
                for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.weight[c], base[c], 1e-6f);
            }
        }
}

TEST(BsdfSpecular, SpecularColorAndStrengthScaleTheHighlight) {
    // A black base leaves only the specular layer: its reflection is
    // specular * specular_color times the white layer's, rough and smooth.
    const Vec3f tint(1.0f, 0.5f, 0.25f);
    const Vec3f wo = world_direction(kNormal, 0.6, 0.4);
    const Vec3f wi = world_direction(kNormal, 0.6, 0.4 + kPiD);  // the mirror direction
    for (float eta : {1.0f / 1.5f, 1.5f}) {
        Bsdf white = Bsdf::make(material(0.0f, 0.3f, 0.0f, 1.5f, Vec3f(0.0f)), kNormal, kNormal, eta);
        Bsdf tinted = Bsdf::make(material(0.0f, 0.3f, 0.0f, 1.5f, Vec3f(0.0f), 0.5f, tint), kNormal, kNormal, eta);
        Vec3f fw = white.eval(wo, wi), ft = tinted.eval(wo, wi);
        ASSERT_GT(fw.x, 0.0f);
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(ft[c], 0.5f * tint[c] * fw[c], 1e-6f * fw[c]);
        // Smooth: the delta mirror, weight s F c / P(mirror) with P(mirror) = 1.
        Bsdf mirror = Bsdf::make(material(0.0f, 0.0f, 0.0f, 1.5f, Vec3f(0.0f), 0.5f, tint), kNormal, kNormal, eta);
        BsdfSample s;
        ASSERT_TRUE(mirror.sample(wo, 0.5f, Vec2f{0.5f, 0.5f}, s));
        ASSERT_TRUE(s.delta);
        float fresnel = float(reference_fresnel(0.6, 1.0 / 1.5));
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(s.weight[c], 0.5f * fresnel * tint[c], 1e-5f);
    }
}

// --- Multiple-scattering compensation -----------------------------------------

TEST(MicrofacetTables, MatchTheSingleScatteringBsdf) {
    // Entries recomputed with the generator's own function at fewer samples:
    // a BSDF change that is not followed by a regenerated table fails here.
    RandomStream rng(15, 0, 1);
    constexpr int kSamples = 1 << 12;
    constexpr double kTolerance = 2e-3;
    for (int n = 0; n < 24; ++n) {
        int k = int(rng.next() * kAlbedoMuCells), j = 1 + int(rng.next() * (kAlbedoRoughnessPoints - 1));
        double e = ggx_albedo_estimate(albedo_grid_mu(k), albedo_grid_roughness(j), kSamples);
        EXPECT_NEAR(ggx_albedo_entry(ggx_albedo_index(k, j)), e, kTolerance) << "mu cell " << k << " roughness " << j;
        int l = int(rng.next() * kAlbedoIorPoints), side = n % 2;
        float ior = albedo_grid_ior(l);
        double g = ggx_dielectric_albedo_estimate(albedo_grid_mu(k), albedo_grid_roughness(j), side ? ior : 1.0f / ior,
                                                  kSamples);
        EXPECT_NEAR(ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, l, j, k)), g, kTolerance)
            << "mu cell " << k << " roughness " << j << " ior " << ior << " side " << side;
    }
    // Sanity: rough GGX loses energy (at alpha = 1 most near normal incidence).
    EXPECT_LT(ggx_albedo(0.9f, 1.0f), 0.4f);
    EXPECT_LT(ggx_albedo(0.5f, 1.0f), 0.8f);
    EXPECT_GT(ggx_albedo(0.5f, 0.1f), 0.99f);
}

TEST(MicrofacetTables, InterpolateAndClamp) {
    // Grid points return their entry; midpoints the mean of the neighbours.
    const int k = 7, j = 12, l = 4;  // ior 1.5
    const float mu = albedo_grid_mu(k), r = albedo_grid_roughness(j), ior = albedo_grid_ior(l);
    EXPECT_FLOAT_EQ(ior, 1.5f);
    EXPECT_FLOAT_EQ(ggx_albedo(mu, r), ggx_albedo_entry(ggx_albedo_index(k, j)));
    float mid_mu = 0.5f * (mu + albedo_grid_mu(k + 1)), mid_r = 0.5f * (r + albedo_grid_roughness(j + 1));
    float corners = ggx_albedo_entry(ggx_albedo_index(k, j)) + ggx_albedo_entry(ggx_albedo_index(k + 1, j)) +
                    ggx_albedo_entry(ggx_albedo_index(k, j + 1)) + ggx_albedo_entry(ggx_albedo_index(k + 1, j + 1));
    EXPECT_NEAR(ggx_albedo(mid_mu, mid_r), 0.25f * corners, 1e-5f);
    EXPECT_NEAR(ggx_albedo(mid_mu, r),
                0.5f * (ggx_albedo_entry(ggx_albedo_index(k, j)) + ggx_albedo_entry(ggx_albedo_index(k + 1, j))), 1e-5f);
    for (int side = 0; side < 2; ++side) {
        float eta = side ? ior : 1.0f / ior;
        EXPECT_NEAR(ggx_dielectric_albedo(mu, r, eta),
                    ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, l, j, k)), 1e-5f);
        float mid_ior = 0.5f * (ior + albedo_grid_ior(l + 1));
        float expected = 0.5f * (ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, l, j, k)) +
                                 ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, l + 1, j, k)));
        EXPECT_NEAR(ggx_dielectric_albedo(mu, r, side ? mid_ior : 1.0f / mid_ior), expected, 1e-5f);
        // Beyond the grid: the edge values.
        const int last_ior = kAlbedoIorPoints - 1, last_mu = kAlbedoMuCells - 1;
        EXPECT_NEAR(ggx_dielectric_albedo(mu, r, side ? 5.0f : 0.2f),
                    ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, last_ior, j, k)), 1e-5f);
        EXPECT_NEAR(ggx_dielectric_albedo(1.0f, r, eta),
                    ggx_dielectric_albedo_entry(ggx_dielectric_albedo_index(side, l, j, last_mu)), 1e-5f);
    }
    EXPECT_FLOAT_EQ(ggx_albedo(0.0f, r), ggx_albedo_entry(ggx_albedo_index(0, j)));
    EXPECT_FLOAT_EQ(ggx_albedo(-1.0f, r), ggx_albedo_entry(ggx_albedo_index(0, j)));
    EXPECT_FLOAT_EQ(ggx_albedo(1.0f, r), ggx_albedo_entry(ggx_albedo_index(kAlbedoMuCells - 1, j)));
    EXPECT_FLOAT_EQ(ggx_albedo(mu, 1.5f), ggx_albedo_entry(ggx_albedo_index(k, kAlbedoRoughnessPoints - 1)));
    EXPECT_FLOAT_EQ(ggx_albedo(mu, -0.5f), ggx_albedo_entry(ggx_albedo_index(k, 0)));
    EXPECT_FLOAT_EQ(ggx_albedo(NAN, NAN), ggx_albedo_entry(ggx_albedo_index(0, 0)));
}

TEST(BsdfCompensation, WhiteConductorAndClearGlassKeepAllEnergy) {
    // Off the grid points too: albedo 1 within noise plus the tables' error,
    // where single scattering alone loses up to half the light.
    constexpr int kSamples = 20000;
    uint32_t seed = 100;
    for (float roughness : {0.1f, 0.37f, 0.6f, 0.85f, 1.0f})
        for (int kind = 0; kind < 3; ++kind) {
            const float ior = 1.45f;
            const float eta = kind == 2 ? ior : 1.0f / ior;  // glass: entering and leaving
            MaterialSample m = material(kind == 0 ? 1.0f : 0.0f, roughness, kind == 0 ? 0.0f : 1.0f, ior);
            Bsdf bsdf = Bsdf::make(m, kNormal, kNormal, eta);
            SingleScatteringBsdf single = SingleScatteringBsdf::make(m, kNormal, kNormal, eta);
            for (double cos_o : {0.95, 0.5, 0.12}) {
                Vec3f wo = world_direction(kNormal, cos_o, 1.7);
                AlbedoEstimate a = estimate_albedo(bsdf, wo, kSamples, ++seed);
                AlbedoEstimate b = estimate_albedo(single, wo, kSamples, seed);
                const Stats& c = a.channel[1];
                EXPECT_NEAR(c.mean(), 1.0, 5.0 * c.standard_error() + kTableTolerance)
                    << "kind " << kind << " roughness " << roughness << " cos " << cos_o;
                EXPECT_LE(b.channel[1].mean(), c.mean() + 1e-6);
                if (roughness >= 0.85f) EXPECT_LT(b.channel[1].mean(), 0.97);  // the loss it makes up for
            }
        }
}

TEST(BsdfCompensation, ChangesWeightsNotThePdf) {
    // Same directions, same densities; only eval (and with it the weights) grows.
    RandomStream rng(16, 0, 1);
    for (float transmission : {0.0f, 1.0f}) {
        MaterialSample m = material(1.0f - transmission, 0.7f, transmission, 1.5f, Vec3f(0.9f, 0.7f, 0.4f));
        Bsdf bsdf = Bsdf::make(m, kNormal, kNormal, 1.0f / 1.5f);
        SingleScatteringBsdf single = SingleScatteringBsdf::make(m, kNormal, kNormal, 1.0f / 1.5f);
        for (int k = 0; k < 2000; ++k) {
            Vec3f wo = world_direction(kNormal, 0.05 + 0.95 * rng.next(), 2.0 * kPiD * rng.next());
            float u_lobe = rng.next();
            Vec2f u = rng.next2();
            BsdfSample a, b;
            bool ok_a = bsdf.sample(wo, u_lobe, u, a), ok_b = single.sample(wo, u_lobe, u, b);
            ASSERT_EQ(ok_a, ok_b);
            if (!ok_a) continue;
            EXPECT_EQ(a.wi, b.wi);
            EXPECT_NEAR(a.pdf, b.pdf, 1e-5f * b.pdf) << "transmission " << transmission;
            EXPECT_GE(a.weight.x, b.weight.x * (1.0f - 1e-6f));
        }
    }
}

TEST(Bsdf, FuzzNeverProducesNanOrNegative) {
    RandomStream rng(13, 0, 2);
    auto unit_random = [&](float edge_probability) {
        float pick = rng.next();
        if (pick < edge_probability) return 0.0f;
        if (pick < 2.0f * edge_probability) return 1.0f;
        return rng.next();
    };
    for (int k = 0; k < 100000; ++k) {
        MaterialSample m = material(unit_random(0.2f), unit_random(0.2f), unit_random(0.3f), 1.0f + 2.0f * unit_random(0.2f),
                                    Vec3f(unit_random(0.1f), unit_random(0.1f), unit_random(0.1f)), unit_random(0.2f),
                                    Vec3f(unit_random(0.1f), unit_random(0.1f), unit_random(0.1f)));
        Vec3f wo = uniform_sphere(rng.next2());
        Vec3f ng = uniform_sphere(rng.next2());
        Vec3f n = normalize(ng + uniform_sphere(rng.next2()) * (0.9f * rng.next()));
        // The contract flips both normals to wo's side; one in eight is left
        // as drawn to check robustness against callers that do not.
        if (rng.next() < 0.875f) {
            if (dot(ng, wo) < 0.0f) ng = -ng;
            if (dot(n, wo) < 0.0f) n = -n;
        }
        float eta = rng.next() < 0.5f ? 1.0f / m.ior : m.ior;
        Bsdf bsdf = Bsdf::make(m, n, ng, eta);
        Vec3f wi = uniform_sphere(rng.next2());
        Vec3f f = bsdf.eval(wo, wi);
        float pdf = bsdf.pdf(wo, wi);
        ASSERT_TRUE(is_finite(f)) << k;
        ASSERT_GE(min_component(f), 0.0f) << k;
        ASSERT_TRUE(is_finite(pdf)) << k;
        ASSERT_GE(pdf, 0.0f) << k;
        BsdfSample s;
        float u_lobe = rng.next();
        if (bsdf.sample(wo, u_lobe, rng.next2(), s)) {
            ASSERT_TRUE(is_finite(s.weight)) << k;
            ASSERT_GE(min_component(s.weight), 0.0f) << k;
            ASSERT_TRUE(is_finite(s.pdf)) << k;
            ASSERT_GT(s.pdf, 0.0f) << k;
            ASSERT_TRUE(is_finite(s.wi)) << k;
            ASSERT_NEAR(length(s.wi), 1.0f, 1e-3f) << k;
        }
        Vec3f albedo = bsdf.albedo();
        ASSERT_TRUE(is_finite(albedo) && min_component(albedo) >= 0.0f && max_component(albedo) <= 1.0f);
    }
}

}  // namespace
}  // namespace rf
