// Light selection and sampling for next-event estimation: Monte Carlo
// irradiance estimates against analytic values (bounds of 5 standard errors
// from the sample variance), agreement of the densities the two MIS
// strategies compute, and importance sampling of equirectangular maps.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "math/color.h"
#include "render/environment_map.h"
#include "render/light_sampling.h"
#include "render/light_set.h"
#include "render_test_scene.h"

namespace rf {
namespace {

constexpr double kPiD = 3.14159265358979323846;

// Uniform floats in [0, 1) from a fixed seed.
struct Uniform {
    std::mt19937 engine;
    explicit Uniform(uint32_t seed) : engine(seed) {}
    float next() { return float(engine() >> 8) * (1.0f / 16777216.0f); }
    Vec2f next2() {
        float a = next();
        return {a, next()};
    }
};

// A scene built in code that also acts as the View sample_light expects.
struct TestWorld : TestScene {
    SceneGeometry geometry;  // the flat triangles the light set is built over (no world here)
    std::vector<ShadingMaterial> materials;
    std::vector<TextureView> textures;
    std::unique_ptr<HostLightSet> light_set;

    uint32_t add_emitter(Vec3f radiance, bool two_sided_emission = false, int32_t texture = kNoTexture) {
        Material m;
        m.base_color = Vec3f(0.0f);
        m.emission = radiance;
        m.emission_texture = texture;
        m.two_sided_emission = two_sided_emission;
        return add_material(m);
    }
    void add_triangle(Vec3f a, Vec3f b, Vec3f c, uint32_t material) {
        Mesh mesh;
        mesh.name = "tri" + std::to_string(scene.meshes.size());
        mesh.positions = {a, b, c};
        mesh.indices = {0, 1, 2};
        mesh.material_ids = {material};
        scene.meshes.push_back(mesh);
    }
    int32_t add_float_texture(int w, int h, std::vector<float> rgb) {
        Texture t;
        t.name = "tex" + std::to_string(scene.textures.size());
        t.width = w;
        t.height = h;
        t.channels = 3;
        t.encoding = TextureEncoding::LinearFloat;
        t.texels_f = std::move(rgb);
        scene.textures.push_back(std::move(t));
        return int32_t(scene.textures.size() - 1);
    }
    void finish() {
        if (scene.materials.empty()) add_material(Material{});
        scene.finalize();
        geometry = SceneGeometry::build(scene);
        for (const Material& m : scene.materials) materials.push_back(ShadingMaterial::from(m));
        for (const Texture& t : scene.textures) textures.push_back(make_texture_view(t));
        light_set = std::make_unique<HostLightSet>(scene, geometry, materials);
    }
    const LightSet& lights() const { return light_set->view(); }

    // --- the View interface ---
    const ShadingMaterial& material(uint32_t id) const { return materials[id < materials.size() ? id : 0]; }
    const TextureView* texture(int32_t id) const {
        return (id >= 0 && size_t(id) < textures.size()) ? &textures[size_t(id)] : nullptr;
    }
    SurfaceHit emitter_surface(const AreaLightSample& s) const {
        Ray ray;
        Hit hit;
        emitter_ray_hit(s, ray, hit);
        return surface_at(scene, geometry, ray, hit);
    }
};

// Running mean and variance per channel (Welford).
struct Stats {
    double n = 0, mean[3] = {0, 0, 0}, m2[3] = {0, 0, 0};
    void add(Vec3f x) {
        n += 1;
        for (int k = 0; k < 3; ++k) {
            double d = double(x[k]) - mean[k];
            mean[k] += d / n;
            m2[k] += d * (double(x[k]) - mean[k]);
        }
    }
    double standard_error(int k) const { return std::sqrt(m2[k] / (n - 1) / n); }
};

// Irradiance at p on a surface with unit normal n from N next-event samples,
// occlusion ignored: sum of radiance * cos / pdf.
Stats estimate_irradiance(const TestWorld& w, Vec3f p, Vec3f n, int count, uint32_t seed) {
    Uniform rng(seed);
    Stats stats;
    for (int i = 0; i < count; ++i) {
        float u_select = rng.next();
        Vec2f u = rng.next2();
        LightSample s;
        Vec3f value(0.0f);
        if (sample_light(w, w.lights(), p, u_select, u, s)) {
            float c = dot(s.wi, n);
            if (c > 0.0f) value = s.radiance * (c / s.pdf);
        }
        stats.add(value);
    }
    return stats;
}

// |estimate - expected| within 5 standard errors; deterministic estimates
// (zero variance) get a float-rounding allowance only.
void expect_within_five_sigma(const Stats& s, Vec3f expected, const char* what) {
    for (int k = 0; k < 3; ++k) {
        double bound = 5.0 * s.standard_error(k) + 1e-5 * std::fmax(std::fabs(expected[k]), 1e-6);
        EXPECT_NEAR(s.mean[k], expected[k], bound) << what << " channel " << k;
    }
}

// Irradiance from a polygon of uniform radiance L above the receiver's
// plane (Lambert's formula): E = L/2 * sum over edges of angle * (n . unit normal of the edge's plane).
double polygon_irradiance(const std::vector<Vec3f>& vertices, Vec3f p, Vec3f n, double radiance) {
    double sum = 0.0;
    for (size_t i = 0; i < vertices.size(); ++i) {
        Vec3f a = normalize(vertices[i] - p), b = normalize(vertices[(i + 1) % vertices.size()] - p);
        double angle = std::acos(std::fmax(-1.0, std::fmin(1.0, double(dot(a, b)))));
        sum += angle * double(dot(n, normalize(cross(a, b))));
    }
    return 0.5 * radiance * std::fabs(sum);
}

bool triangle_contains(const Triangle& t, Vec3f q) {
    Vec3f n = t.geometric_normal();
    float tol = -1e-4f * dot(n, n);
    if (std::fabs(dot(q - t.v0, n)) > 1e-4f * length(n)) return false;  // off the triangle's plane
    return dot(cross(t.v1 - t.v0, q - t.v0), n) >= tol && dot(cross(t.v2 - t.v1, q - t.v1), n) >= tol &&
           dot(cross(t.v0 - t.v2, q - t.v2), n) >= tol;
}

Light point_light(Vec3f position, Vec3f color, float intensity) {
    Light l;
    l.type = LightType::Point;
    l.position = position;
    l.color = color;
    l.intensity = intensity;
    return l;
}

Light spot_light(Vec3f position, Vec3f direction, float intensity, float inner, float outer) {
    Light l;
    l.type = LightType::Spot;
    l.position = position;
    l.direction = direction;
    l.intensity = intensity;
    l.inner_cone_radians = inner;
    l.outer_cone_radians = outer;
    return l;
}

Light directional_light(Vec3f direction, Vec3f color, float irradiance) {
    Light l;
    l.type = LightType::Directional;
    l.direction = direction;
    l.color = color;
    l.intensity = irradiance;
    return l;
}

// A w x h map of random radiance (a few black texels, one hot texel).
std::vector<float> random_map(int w, int h, uint32_t seed) {
    Uniform rng(seed);
    std::vector<float> rgb(size_t(w * h * 3));
    for (int i = 0; i < w * h; ++i) {
        float scale = rng.next() < 0.2f ? 0.0f : -std::log(1.0f - rng.next());
        for (int k = 0; k < 3; ++k) rgb[size_t(i * 3 + k)] = scale * (0.2f + rng.next());
    }
    int hot = (h / 2) * w + w / 3;
    for (int k = 0; k < 3; ++k) rgb[size_t(hot * 3 + k)] = 40.0f;
    return rgb;
}

// Direction at map coordinates (u, v), the inverse of the equirectangular mapping.
Vec3f direction_at(double u, double v, double rotation) {
    double theta = v * kPiD, phi = (u - 0.5) * 2.0 * kPiD - rotation;
    return Vec3f(float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)),
                 float(-std::sin(theta) * std::cos(phi)));
}

// Integral of luminance over the sphere by the midpoint rule on a grid 16x
// finer than the map (texel centres fall on grid lines, so the bilinear
// interpolant is smooth inside every cell).
double luminance_integral(const EnvironmentLight& env, int w, int h) {
    const int nu = 16 * w, nv = 16 * h;
    double sum = 0.0;
    for (int j = 0; j < nv; ++j) {
        double v = (j + 0.5) / nv;
        double row = 0.0;
        for (int i = 0; i < nu; ++i) row += luminance(env.radiance(direction_at((i + 0.5) / nu, v, env.rotation_radians)));
        sum += row * std::sin(v * kPiD);
    }
    return sum * (2.0 * kPiD / nu) * (kPiD / nv);
}

// ---------------------------------------------------------------- delta lights

TEST(LightSamplingDelta, PointLightFollowsInverseSquareAndCosine) {
    TestWorld w;
    w.scene.lights.push_back(point_light({1, 3, 0}, {1.0f, 0.5f, 0.25f}, 7.0f));
    w.finish();
    Vec3f p(0, 0, 0), n = normalize(Vec3f(0.2f, 1, 0));
    Vec3f to = Vec3f(1, 3, 0) - p;
    float d2 = dot(to, to);
    float cosine = dot(normalize(to), n);
    Stats s = estimate_irradiance(w, p, n, 64, 1);
    expect_within_five_sigma(s, Vec3f(1.0f, 0.5f, 0.25f) * (7.0f * cosine / d2), "point");

    LightSample ls;
    ASSERT_TRUE(sample_light(w, w.lights(), p, 0.3f, Vec2f{0.1f, 0.9f}, ls));
    EXPECT_TRUE(ls.delta);
    EXPECT_FLOAT_EQ(ls.pdf, 1.0f);
    EXPECT_NEAR(ls.distance, std::sqrt(d2), 1e-5f);
}

TEST(LightSamplingDelta, SpotInsideBetweenAndOutsideTheCone) {
    const float inner = 0.3f, outer = 0.6f, intensity = 5.0f;
    TestWorld w;
    w.scene.lights.push_back(spot_light({0, 2, 0}, {0, -1, 0}, intensity, inner, outer));
    w.finish();
    Vec3f n(0, 1, 0);
    auto irradiance_at = [&](float angle) {
        Vec3f p(2.0f * std::tan(angle), 0, 0);
        return estimate_irradiance(w, p, n, 16, 2);
    };
    auto expected = [&](float angle, float falloff) {
        float d = 2.0f / std::cos(angle);
        return Vec3f(intensity * falloff * std::cos(angle) / (d * d));
    };
    expect_within_five_sigma(irradiance_at(0.0f), expected(0.0f, 1.0f), "on the axis");
    expect_within_five_sigma(irradiance_at(0.2f), expected(0.2f, 1.0f), "inside the inner cone");
    float between = 0.45f;
    float t = (std::cos(between) - std::cos(outer)) / (std::cos(inner) - std::cos(outer));
    expect_within_five_sigma(irradiance_at(between), expected(between, t * t), "between the cones");
    expect_within_five_sigma(irradiance_at(0.7f), Vec3f(0.0f), "outside the outer cone");
    EXPECT_FLOAT_EQ(spot_falloff(w.scene.lights[0], std::cos(between)), t * t);
}

TEST(LightSamplingDelta, DirectionalIrradianceIsCosineWeighted) {
    TestWorld w;
    Vec3f travel = normalize(Vec3f(1, -2, 0.5f));
    w.scene.lights.push_back(directional_light(travel, {0.5f, 1.0f, 2.0f}, 3.0f));
    w.finish();
    Vec3f n(0, 1, 0);
    Stats s = estimate_irradiance(w, {4, -1, 2}, n, 16, 3);
    expect_within_five_sigma(s, Vec3f(0.5f, 1.0f, 2.0f) * (3.0f * dot(-travel, n)), "directional");
    LightSample ls;
    ASSERT_TRUE(sample_light(w, w.lights(), Vec3f(0.0f), 0.5f, Vec2f{0.5f, 0.5f}, ls));
    EXPECT_EQ(ls.distance, kInfinity);
    EXPECT_TRUE(ls.delta);
}

TEST(LightSamplingDelta, MixedLightsEstimateTheirSum) {
    TestWorld w;
    w.scene.lights.push_back(point_light({0, 2, 0}, {1, 1, 1}, 4.0f));
    w.scene.lights.push_back(point_light({3, 1, -1}, {1, 0.2f, 0.2f}, 20.0f));
    w.scene.lights.push_back(spot_light({-1, 3, 0}, normalize(Vec3f(0.3f, -1, 0)), 10.0f, 0.2f, 0.5f));
    w.scene.lights.push_back(directional_light({0, -1, 0}, {0.3f, 0.3f, 1.0f}, 0.5f));
    w.finish();
    Vec3f p(0, 0, 0), n(0, 1, 0);
    Vec3f expected(0.0f);
    for (const Light& l : w.scene.lights) {
        if (l.type == LightType::Directional) {
            expected += l.color * (l.intensity * std::fmax(0.0f, dot(-normalize(l.direction), n)));
            continue;
        }
        Vec3f to = l.position - p;
        float d2 = dot(to, to);
        Vec3f wi = normalize(to);
        float falloff = l.type == LightType::Spot ? spot_falloff(l, dot(-wi, normalize(l.direction))) : 1.0f;
        expected += l.color * (l.intensity * falloff * std::fmax(0.0f, dot(wi, n)) / d2);
    }
    Stats s = estimate_irradiance(w, p, n, 20000, 4);
    expect_within_five_sigma(s, expected, "sum of delta lights");
    EXPECT_GT(s.standard_error(0), 0.0);  // selection really varied
}

// ---------------------------------------------------------------- area lights

TEST(LightSamplingArea, EmissiveQuadMatchesLambertsPolygonFormula) {
    const Vec3f centre(0.3f, 1.0f, 0.2f), half_u(0.7f, 0, 0), half_v(0, 0, 0.5f);  // faces -y
    const Vec3f radiance(2.0f, 1.0f, 0.5f);
    for (bool with_point_light : {false, true}) {
        TestWorld w;
        w.add_quad(centre, half_u, half_v, w.add_emitter(radiance));
        if (with_point_light) w.scene.lights.push_back(point_light({5, 5, 5}, {1, 1, 1}, 1.0f));
        w.finish();
        ASSERT_EQ(w.lights().emitters.count, 2u);
        Vec3f p(0, 0, 0), n = normalize(Vec3f(0.1f, 1, -0.2f));
        std::vector<Vec3f> quad = {centre - half_u - half_v, centre + half_u - half_v, centre + half_u + half_v,
                                   centre - half_u + half_v};
        double e = polygon_irradiance(quad, p, n, 1.0);
        Vec3f expected = radiance * float(e);
        if (with_point_light) {
            Vec3f to = Vec3f(5, 5, 5) - p;
            expected += Vec3f(std::fmax(0.0f, dot(normalize(to), n)) / dot(to, to));
        }
        Stats s = estimate_irradiance(w, p, n, 40000, 5);
        expect_within_five_sigma(s, expected, with_point_light ? "quad and point light" : "quad");
    }
}

TEST(LightSamplingArea, OneSidedEmittersAreDarkFromBehindDoubleSidedAreNot) {
    const Vec3f centre(0, 1, 0), half_u(0.5f, 0, 0), half_v(0, 0, 0.5f);  // faces -y
    for (bool two_sided_emission : {false, true}) {
        TestWorld w;
        w.add_quad(centre, half_u, half_v, w.add_emitter(Vec3f(1.0f), two_sided_emission));
        w.finish();
        Vec3f above(0.1f, 2.0f, 0.0f), down(0, -1, 0);
        Stats s = estimate_irradiance(w, above, down, 20000, 6);
        std::vector<Vec3f> quad = {centre - half_u - half_v, centre + half_u - half_v, centre + half_u + half_v,
                                   centre - half_u + half_v};
        float expected = two_sided_emission ? float(polygon_irradiance(quad, above, down, 1.0)) : 0.0f;
        expect_within_five_sigma(s, Vec3f(expected), two_sided_emission ? "double-sided back" : "one-sided back");
    }
}

TEST(LightSamplingArea, EmissionTextureScalesTheRadiance) {
    TestWorld w;
    int32_t tex = w.add_float_texture(1, 1, {0.5f, 0.25f, 2.0f});
    const Vec3f centre(0, 1, 0), half_u(0.5f, 0, 0), half_v(0, 0, 0.5f);
    w.add_quad(centre, half_u, half_v, w.add_emitter(Vec3f(2.0f), false, tex));
    w.finish();
    Vec3f p(0, 0, 0), n(0, 1, 0);
    std::vector<Vec3f> quad = {centre - half_u - half_v, centre + half_u - half_v, centre + half_u + half_v,
                               centre - half_u + half_v};
    float e = float(polygon_irradiance(quad, p, n, 1.0));
    Stats s = estimate_irradiance(w, p, n, 20000, 7);
    expect_within_five_sigma(s, Vec3f(1.0f, 0.5f, 4.0f) * e, "textured emitter");
}

// A unit quad in y = 1 facing -y, split into `columns` strips of two
// triangles each, with uvs u = x and v = z over [0, 1]^2.
void add_uv_quad(TestWorld& w, int columns, uint32_t material) {
    Mesh mesh;
    mesh.name = "uv_quad";
    for (int i = 0; i <= columns; ++i)
        for (float z : {0.0f, 1.0f}) {
            const float x = float(i) / float(columns);
            mesh.positions.push_back({x, 1.0f, z});
            mesh.uvs.push_back({x, z});
        }
    for (uint32_t i = 0; i < uint32_t(columns); ++i) {
        const uint32_t a = 2 * i, b = 2 * i + 1, c = 2 * i + 2, d = 2 * i + 3;  // a, c at z = 0
        mesh.indices.insert(mesh.indices.end(), {a, c, d, a, d, b});       // wound to face -y
        mesh.material_ids.insert(mesh.material_ids.end(), {material, material});
    }
    w.scene.meshes.push_back(mesh);
}

// The mean of the bilinear emission texture over triangle t of the
// geometry, on a dense barycentric grid: the reference for the table.
double brute_force_power(const TestWorld& w, uint32_t t, int n = 400) {
    const uint32_t* idx = &w.scene.meshes[0].indices[3 * size_t(w.geometry.local_triangle[t])];
    const std::vector<Vec2f>& uv = w.scene.meshes[0].uvs;
    const ShadingMaterial& m = w.material(w.geometry.material[t]);
    double sum = 0.0;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            Vec2f b = sample_uniform_triangle({(float(i) + 0.5f) / float(n), (float(j) + 0.5f) / float(n)});
            Vec2f p = uv[idx[0]] * (1.0f - b.x - b.y) + uv[idx[1]] * b.x + uv[idx[2]] * b.y;
            Vec4f c = sample_texture(*w.texture(m.emission_texture), p);
            sum += luminance(m.emission * Vec3f(c.x, c.y, c.z));
        }
    return sum / double(n) / double(n) * double(w.geometry.triangles[t].area());
}

// Emission texture black on the left half (with margin for the bilinear
// filter) and white on the right: the black triangles are not lights, the
// others are chosen in proportion to their textured power, and the light
// samples still estimate the irradiance of the whole quad.
TEST(LightSamplingArea, EmissionTexturesWeighTheEmitterTable) {
    TestWorld w;
    std::vector<float> rgb;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 64; ++x)
            for (int k = 0; k < 3; ++k) rgb.push_back(x < 33 ? 0.0f : 1.0f);  // black past u = 0.5 + half a texel
    int32_t tex = w.add_float_texture(64, 4, rgb);
    w.scene.textures.back().wrap_s = TextureWrap::ClampToEdge;
    add_uv_quad(w, 8, w.add_emitter(Vec3f(3.0f), false, tex));
    w.finish();
    const LightSet& lights = w.lights();
    ASSERT_EQ(lights.emitters.count, 8u);  // 8 of 16 triangles lie in the black half
    double total = 0.0;
    for (uint32_t t = 0; t < w.geometry.triangles.size(); ++t) total += brute_force_power(w, t);
    for (uint32_t t = 0; t < w.geometry.triangles.size(); ++t) {
        const uint32_t i = lights.emitter_index(t);
        const double expected = brute_force_power(w, t) / total;
        if (expected == 0.0) {
            EXPECT_EQ(i, lights.emitters.count) << "black triangle " << t << " in the table";
            continue;
        }
        ASSERT_LT(i, lights.emitters.count) << "triangle " << t;
        const float probability = lights.emitters.cdf[i] - (i > 0 ? lights.emitters.cdf[i - 1] : 0.0f);
        EXPECT_NEAR(probability, expected, 0.01 * expected) << "triangle " << t;
    }

    // Reference irradiance below the quad by uniform area sampling of all of it.
    const Vec3f p(0.3f, 0.0f, 0.4f), n(0, 1, 0);
    Uniform rng(21);
    double reference = 0.0;
    const int m = 400000;
    for (int i = 0; i < m; ++i) {
        Vec2f u = rng.next2();
        Vec3f q(u.x, 1.0f, u.y), d = q - p;
        float d2 = dot(d, d);
        float cos_both = dot(normalize(d), n) * dot(normalize(d), n);  // receiver and light normals are parallel
        Vec4f c = sample_texture(w.textures[size_t(tex)], u);
        reference += 3.0 * c.x * cos_both / d2;
    }
    reference /= m;
    Stats s = estimate_irradiance(w, p, n, 40000, 22);
    EXPECT_NEAR(s.mean[0], reference, 5.0 * s.standard_error(0) + 3e-3 * reference);
}

TEST(LightSamplingSelection, TwoSidedEmittersWeighTwiceAsMuch) {
    TestWorld w;
    w.add_quad({0, 1, 0}, {0.5f, 0, 0}, {0, 0, 0.5f}, w.add_emitter(Vec3f(1.0f), false));
    w.add_quad({3, 1, 0}, {0.5f, 0, 0}, {0, 0, 0.5f}, w.add_emitter(Vec3f(1.0f), true));
    w.scene.lights.push_back(point_light({0, 3, 0}, {1, 1, 1}, 1.0f));
    w.finish();
    const LightSet& lights = w.lights();
    ASSERT_EQ(lights.emitters.count, 4u);
    for (uint32_t i = 0; i < 4; ++i) {
        const float probability = lights.emitters.cdf[i] - (i > 0 ? lights.emitters.cdf[i - 1] : 0.0f);
        EXPECT_NEAR(probability, i < 2 ? 1.0f / 6.0f : 2.0f / 6.0f, 1e-6f) << "emitter " << i;
    }
    // The area group's flux: pi L A per face, both faces of the second quad.
    const double area_power = kPiD * (1.0 + 2.0), point_power = 4.0 * kPiD;
    EXPECT_NEAR(lights.selection_probability(lights.area_entry()), area_power / (area_power + point_power), 1e-6);
}

TEST(LightSamplingArea, AreaLightPdfEqualsTheSampledPdf) {
    TestWorld w;
    // Emitters of different area and radiance, so the table is not uniform.
    w.add_triangle({-1, 2, -1}, {1, 2, -1}, {0, 2, 1}, w.add_emitter(Vec3f(3.0f)));
    w.add_triangle({2, 1, 0}, {2, 1.5f, 0.5f}, {2.5f, 1, 0}, w.add_emitter(Vec3f(1.0f, 8.0f, 1.0f), true));
    w.add_quad({-2, 1, 0}, {0, 0, 0.3f}, {0, 0.3f, 0}, w.add_emitter(Vec3f(0.5f), true));
    w.scene.lights.push_back(point_light({0, 5, 0}, {1, 1, 1}, 3.0f));
    w.finish();
    const LightSet& lights = w.lights();
    ASSERT_EQ(lights.emitters.count, 4u);
    Uniform rng(8);
    Vec3f p(0.2f, 0.0f, 0.1f);
    int area_samples = 0;
    for (int i = 0; i < 4000; ++i) {
        LightSample s;
        if (!sample_light(w, lights, p, rng.next(), rng.next2(), s) || s.delta) continue;
        Vec3f hit = p + s.wi * s.distance;
        uint32_t prim = kInvalidId;
        for (uint32_t t = 0; t < w.geometry.triangles.size(); ++t)
            if (triangle_contains(w.geometry.triangles[t], hit)) prim = t;
        ASSERT_NE(prim, kInvalidId);
        float pdf = area_light_pdf(w, lights, prim, p, hit, s.wi);
        ASSERT_NEAR(pdf, s.pdf, 1e-3f * s.pdf) << "sample " << i;
        ++area_samples;
    }
    EXPECT_GT(area_samples, 1000);
    EXPECT_EQ(area_light_pdf(w, lights, 99, p, Vec3f(0, 2, 0), Vec3f(0, 1, 0)), 0.0f);  // not an emitter
}

// ---------------------------------------------------------------- environment

TEST(LightSamplingEnvironment, ConstantEnvironmentGivesPiTimesRadiance) {
    const Vec3f radiance(0.4f, 0.8f, 1.2f);
    for (bool with_point_light : {false, true}) {
        TestWorld w;
        w.scene.environment.color = radiance;
        w.scene.environment.strength = 2.0f;
        if (with_point_light) w.scene.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}, 1.0f));
        w.finish();
        Vec3f expected = radiance * (2.0f * float(kPiD)) + Vec3f(with_point_light ? 1.0f : 0.0f);
        Stats s = estimate_irradiance(w, Vec3f(0.0f), Vec3f(0, 1, 0), 40000, 9);
        expect_within_five_sigma(s, expected, with_point_light ? "environment and point light" : "environment");
    }
}

TEST(LightSamplingEnvironment, EnvironmentLightPdfEqualsTheSampledPdf) {
    TestWorld w;
    w.scene.environment.texture = w.add_float_texture(16, 8, random_map(16, 8, 10));
    w.scene.environment.rotation_radians = 0.7f;
    w.scene.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}, 1.0f));
    w.finish();
    const LightSet& lights = w.lights();
    float env_selection = lights.selection_probability(lights.environment_entry());
    ASSERT_GT(env_selection, 0.0f);
    ASSERT_LT(env_selection, 1.0f);
    Uniform rng(11);
    int checked = 0;
    for (int i = 0; i < 4000; ++i) {
        LightSample s;
        if (!sample_light(w, lights, Vec3f(0.0f), rng.next(), rng.next2(), s) || s.delta) continue;
        EXPECT_EQ(s.distance, kInfinity);
        if (std::fabs(s.wi.y) > 0.99f) continue;
        ASSERT_NEAR(environment_light_pdf(lights, s.wi), s.pdf, 1e-3f * s.pdf) << "sample " << i;
        ++checked;
    }
    EXPECT_GT(checked, 500);
}

TEST(LightSamplingEnvironment, ImportanceSampledMapIrradianceIsUnbiased) {
    // Irradiance of an upward-facing point under a random map, against quadrature.
    TestWorld w;
    w.scene.environment.texture = w.add_float_texture(8, 4, random_map(8, 4, 12));
    w.finish();
    const EnvironmentLight& env = w.lights().environment;
    const int nu = 128, nv = 64;
    Vec3f reference(0.0f);
    for (int j = 0; j < nv / 2; ++j) {  // upper hemisphere: v in [0, 1/2]
        double v = (j + 0.5) / nv;
        for (int i = 0; i < nu; ++i) {
            Vec3f d = direction_at((i + 0.5) / nu, v, 0.0);
            reference += env.radiance(d) * float(d.y * std::sin(v * kPiD) * (2.0 * kPiD / nu) * (kPiD / nv));
        }
    }
    Stats s = estimate_irradiance(w, Vec3f(0.0f), Vec3f(0, 1, 0), 60000, 13);
    for (int k = 0; k < 3; ++k)  // midpoint quadrature is accurate to ~1e-4 here
        EXPECT_NEAR(s.mean[k], reference[k], 5.0 * s.standard_error(k) + 2e-4 * reference[k]) << k;
}

// ---------------------------------------------------------------- selection

TEST(LightSamplingSelection, ProbabilitiesFollowPower) {
    TestWorld w;
    w.scene.lights.push_back(point_light({0, 3, 0}, {1, 0.5f, 0.2f}, 2.0f));
    w.scene.lights.push_back(spot_light({1, 3, 0}, {0, -1, 0}, 30.0f, 0.1f, 0.4f));
    w.scene.lights.push_back(directional_light({0, -1, 0}, {1, 1, 1}, 0.25f));
    w.add_quad({0, 2, 0}, {0, 0, 0.5f}, {1.0f, 0, 0}, w.add_emitter(Vec3f(3.0f, 2.0f, 1.0f)));
    w.add_quad({0, 0, 0}, {2, 0, 0}, {0, 0, 1}, w.add_material(Material{}));  // grows the bounds
    w.scene.environment.color = Vec3f(0.1f, 0.2f, 0.3f);
    w.finish();
    const LightSet& lights = w.lights();
    ASSERT_EQ(lights.selection_count, 5u);
    Box3f b = w.geometry.bounds;
    double r = 0.5 * double(length(b.extent()));
    EXPECT_NEAR(lights.scene_radius, r, 1e-6 * r);
    double powers[5] = {
        4.0 * kPiD * 2.0 * double(luminance(Vec3f(1, 0.5f, 0.2f))),
        2.0 * kPiD * (1.0 - std::cos(0.4)) * 30.0,
        0.25 * kPiD * r * r,
        kPiD * (2.0 * 1.0) * double(luminance(Vec3f(3, 2, 1))),  // pi * area * luminance
        kPiD * r * r * kPiD * double(luminance(Vec3f(0.1f, 0.2f, 0.3f))),
    };
    double total = 0.0;
    for (double p : powers) total += p;
    for (uint32_t i = 0; i < 5; ++i)
        EXPECT_NEAR(lights.selection_probability(i), powers[i] / total, 1e-5) << "entry " << i;
    EXPECT_EQ(lights.area_entry(), 3u);
    EXPECT_EQ(lights.environment_entry(), 4u);

    // Empirical frequencies of select() agree (5 sigma of a binomial count).
    Uniform rng(14);
    const int n = 100000;
    int counts[5] = {0, 0, 0, 0, 0};
    for (int i = 0; i < n; ++i) {
        float probability, u_within;
        uint32_t e = lights.select(rng.next(), probability, u_within);
        ASSERT_LT(e, 5u);
        ASSERT_GE(u_within, 0.0f);
        ASSERT_LT(u_within, 1.0f);
        ++counts[e];
    }
    for (int i = 0; i < 5; ++i) {
        double pr = powers[i] / total;
        EXPECT_NEAR(counts[i], n * pr, 5.0 * std::sqrt(n * pr * (1.0 - pr)) + 1.0) << "entry " << i;
    }
}

TEST(LightSamplingSelection, ZeroPowerLightsAreNeverChosenAndAllZeroIsUniform) {
    TestWorld w;
    w.scene.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}, 0.0f));
    w.scene.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}, 2.0f));
    w.scene.lights.push_back(point_light({0, 1, 0}, {0, 0, 0}, 5.0f));
    w.finish();
    const LightSet& lights = w.lights();
    EXPECT_EQ(lights.selection_probability(0), 0.0f);
    EXPECT_EQ(lights.selection_probability(1), 1.0f);
    EXPECT_EQ(lights.selection_probability(2), 0.0f);
    for (float u : {0.0f, 0.3f, 0.99999994f}) {
        float probability, u_within;
        EXPECT_EQ(lights.select(u, probability, u_within), 1u);
    }

    TestWorld dark;
    dark.scene.lights.push_back(point_light({0, 1, 0}, {1, 1, 1}, 0.0f));
    dark.scene.lights.push_back(directional_light({0, -1, 0}, {0, 0, 0}, 1.0f));
    dark.finish();
    EXPECT_EQ(dark.lights().selection_count, 2u);
    EXPECT_FLOAT_EQ(dark.lights().selection_probability(0), 0.5f);
    EXPECT_FLOAT_EQ(dark.lights().selection_probability(1), 0.5f);

    TestWorld empty;
    empty.finish();
    EXPECT_EQ(empty.lights().selection_count, 0u);
    LightSample s;
    EXPECT_FALSE(sample_light(empty, empty.lights(), Vec3f(0.0f), 0.5f, Vec2f{0.5f, 0.5f}, s));
    EXPECT_EQ(environment_light_pdf(empty.lights(), Vec3f(0, 1, 0)), 0.0f);
}

// ---------------------------------------------------------------- environment maps

EnvironmentLight map_light(Scene& scene, int w, int h, std::vector<float> rgb, float rotation, int max_width = 2048,
                           std::unique_ptr<EnvironmentDistribution>* owner = nullptr) {
    Texture t;
    t.width = w;
    t.height = h;
    t.channels = 3;
    t.encoding = TextureEncoding::LinearFloat;
    t.texels_f = std::move(rgb);
    scene.textures = {std::move(t)};
    scene.environment.texture = 0;
    scene.environment.rotation_radians = rotation;
    *owner = std::make_unique<EnvironmentDistribution>(scene, max_width);
    return (*owner)->light();
}

TEST(EnvironmentMap, RadianceFollowsTheEquirectangularMapping) {
    const int w = 8, h = 4;
    std::vector<float> rgb(size_t(w * h * 3));
    for (int i = 0; i < w * h * 3; ++i) rgb[size_t(i)] = float(i) * 0.1f;
    for (float rotation : {0.0f, 1.3f}) {
        Scene scene;
        std::unique_ptr<EnvironmentDistribution> owner;
        EnvironmentLight env = map_light(scene, w, h, rgb, rotation, 2048, &owner);
        env.strength = 2.0f;
        for (int y = 0; y < h; ++y)
            for (int x = 0; x < w; ++x) {  // at texel centres the bilinear lookup is the texel itself
                Vec3f d = direction_at((x + 0.5) / w, (y + 0.5) / h, rotation);
                Vec3f c = env.radiance(d);
                size_t base = size_t((y * w + x) * 3);
                for (int k = 0; k < 3; ++k) EXPECT_NEAR(c[k], 2.0f * rgb[base + k], 1e-3f) << x << "," << y;
            }
    }
    // Without rotation u = 0.5 looks down -z and v = 0 straight up.
    Scene scene;
    std::unique_ptr<EnvironmentDistribution> owner;
    EnvironmentLight env = map_light(scene, 2, 1, {1, 0, 0, 0, 1, 0}, 0.0f, 2048, &owner);
    Vec3f minus_z = env.radiance(Vec3f(0, 0, -1));  // u = 1/2: halfway between the texel centres 1/4 and 3/4
    EXPECT_NEAR(minus_z.x, 0.5f, 1e-5f);
    EXPECT_NEAR(minus_z.y, 0.5f, 1e-5f);
    EXPECT_NEAR(env.radiance(Vec3f(-1, 0, 0)).x, 1.0f, 1e-5f);  // u = 1/4: texel 0
    EXPECT_NEAR(env.radiance(Vec3f(1, 0, 0)).y, 1.0f, 1e-5f);   // u = 3/4: texel 1
}

TEST(EnvironmentMap, BrightTexelAttractsAlmostAllSamples) {
    const int w = 32, h = 16, hot_x = 21, hot_y = 5;
    std::vector<float> rgb(size_t(w * h * 3), 0.01f);
    for (int k = 0; k < 3; ++k) rgb[size_t((hot_y * w + hot_x) * 3 + k)] = 1000.0f;
    Scene scene;
    std::unique_ptr<EnvironmentDistribution> owner;
    EnvironmentLight env = map_light(scene, w, h, rgb, 0.4f, 2048, &owner);
    ASSERT_TRUE(env.emits());
    Uniform rng(15);
    const int n = 20000;
    int near_hot = 0, in_hot = 0;
    for (int i = 0; i < n; ++i) {
        Vec3f d;
        float pdf;
        env.sample(rng.next2(), d, pdf);
        ASSERT_GT(pdf, 0.0f);
        double u = 0.5 + (std::atan2(double(d.x), double(-d.z)) + 0.4) / (2.0 * kPiD);
        u -= std::floor(u);
        double v = std::acos(std::fmax(-1.0, std::fmin(1.0, double(d.y)))) / kPiD;
        int x = int(u * w), y = int(v * h);
        if (x == hot_x && y == hot_y) ++in_hot;
        if (std::abs(x - hot_x) <= 1 && std::abs(y - hot_y) <= 1) ++near_hot;
    }
    // The hot texel's bilinear footprint holds > 99.9% of the map's light:
    // 9/16 of it inside the texel itself, the rest in its 8 neighbours.
    EXPECT_GT(near_hot, int(0.99 * n));
    EXPECT_GT(in_hot, int(0.5 * n));
}

TEST(EnvironmentMap, SamplePdfMatchesPdfOnARandomMap) {
    for (int max_width : {2048, 16}) {  // full resolution and a downsampled distribution
        Scene scene;
        std::unique_ptr<EnvironmentDistribution> owner;
        EnvironmentLight env = map_light(scene, 64, 32, random_map(64, 32, 16), 2.5f, max_width, &owner);
        EXPECT_EQ(env.width, max_width == 16 ? 16 : 64);
        Uniform rng(17);
        int checked = 0;
        for (int i = 0; i < 20000; ++i) {
            Vec3f d;
            float pdf;
            Vec3f radiance = env.sample(rng.next2(), d, pdf);
            if (std::fabs(d.y) > 0.999f) continue;
            ASSERT_NEAR(length(d), 1.0f, 1e-5f);
            ASSERT_NEAR(env.pdf(d), pdf, 1e-3f * pdf) << "sample " << i;
            // sample() looks the map up at the sampled (u, v) directly; the
            // round trip through the direction differs by float error only.
            Vec3f expected = env.radiance(d);
            for (int k = 0; k < 3; ++k) ASSERT_NEAR(radiance[k], expected[k], 1e-3f * std::fmax(expected[k], 1.0f));
            ++checked;
        }
        EXPECT_GT(checked, 19000);
    }
}

TEST(EnvironmentMap, ImportanceSamplingIsUnbiasedEvenBesideBlackTexels) {
    // Integral of luminance over the sphere: importance sampling against
    // quadrature. Black texels next to bright ones still receive light through
    // bilinear filtering; a density of 0 there would bias the estimate low.
    for (int max_width : {2048, 4}) {
        Scene scene;
        std::unique_ptr<EnvironmentDistribution> owner;
        EnvironmentLight env = map_light(scene, 8, 4, random_map(8, 4, 18), 0.9f, max_width, &owner);
        double reference = luminance_integral(env, 8, 4);
        EXPECT_NEAR(env.average_luminance * 4.0 * kPiD, reference, 2e-4 * reference);
        Uniform rng(19);
        Stats s;
        for (int i = 0; i < 100000; ++i) {
            Vec3f d;
            float pdf;
            Vec3f radiance = env.sample(rng.next2(), d, pdf);
            s.add(Vec3f(pdf > 0.0f ? luminance(radiance) / pdf : 0.0f));
        }
        EXPECT_NEAR(s.mean[0], reference, 5.0 * s.standard_error(0) + 2e-4 * reference) << "max width " << max_width;
        // The support condition directly: wherever light arrives, the density is positive.
        int uncovered = 0;
        for (int j = 0; j < 64; ++j)
            for (int i = 0; i < 128; ++i) {
                Vec3f d = direction_at((i + 0.5) / 128, (j + 0.5) / 64, env.rotation_radians);
                if (luminance(env.radiance(d)) > 0.0f && !(env.pdf(d) > 0.0f)) ++uncovered;
            }
        EXPECT_EQ(uncovered, 0) << "max width " << max_width;
    }
}

TEST(EnvironmentMap, ConstantAndBlackEnvironments) {
    Scene scene;
    scene.environment.color = Vec3f(1, 2, 3);
    scene.environment.strength = 0.5f;
    EnvironmentDistribution constant(scene);
    EnvironmentLight env = constant.light();
    EXPECT_TRUE(env.emits());
    EXPECT_FALSE(env.map.valid());
    Vec3f d;
    float pdf;
    Vec3f radiance = env.sample(Vec2f{0.3f, 0.6f}, d, pdf);
    EXPECT_NEAR(pdf, 0.25f / float(kPiD), 1e-7f);
    EXPECT_NEAR(env.pdf(d), pdf, 1e-7f);
    EXPECT_EQ(radiance, Vec3f(0.5f, 1.0f, 1.5f));
    EXPECT_NEAR(env.power_proxy(2.0f), float(kPiD * 4.0 * kPiD * luminance(Vec3f(0.5f, 1.0f, 1.5f))), 1e-4f);

    std::unique_ptr<EnvironmentDistribution> owner;
    EnvironmentLight black = map_light(scene, 4, 2, std::vector<float>(24, 0.0f), 0.0f, 2048, &owner);
    EXPECT_FALSE(black.emits());
    EXPECT_EQ(black.power_proxy(1.0f), 0.0f);
}

}  // namespace
}  // namespace rf
