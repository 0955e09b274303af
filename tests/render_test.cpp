// The integrators and the tile renderer on small hand-made scenes whose
// answers are known analytically.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/render/render.h"
#include "render/integrators/whitted.h"
#include "render_test_scene.h"

namespace rf {
namespace {

// Where the centre ray of pixel (x, y) meets the plane z = 0.
Vec3f hit_on_ground(const Camera& camera, int x, int y, int w, int h) {
    Ray r = CameraFrame::make(camera, w, h).generate(float(x) + 0.5f, float(y) + 0.5f, w, h);
    return r.org + r.dir * (-r.org.z / r.dir.z);
}

void expect_color_near(Vec3f actual, Vec3f expected, float relative, const char* what) {
    for (int k = 0; k < 3; ++k)
        EXPECT_NEAR(actual[k], expected[k], relative * std::fmax(std::fabs(expected[k]), 1e-3f)) << what << " channel " << k;
}

TEST(RenderNormals, FacingQuadShowsItsNormalWhicheverWayItIsWound) {
    for (bool flipped : {false, true}) {
        TestScene t;
        uint32_t m = t.add_material(diffuse(Vec3f(0.5f)));
        Vec3f u(10, 0, 0), v(0, 10, 0);
        t.add_quad(Vec3f(0.0f), flipped ? v : u, flipped ? u : v, m);
        t.finish();
        Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}), options_for(IntegratorKind::Normals, 8, 6));
        for (const Vec3f& p : image.pixels) expect_color_near(p, Vec3f(0.5f, 0.5f, 1.0f), 1e-5f, "normal");
    }
}

TEST(RenderNormals, BackgroundIsBlack) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {1, 0, 0}, {0, 1, 0}, t.add_material(diffuse(Vec3f(0.5f))));
    t.finish();
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 10}), options_for(IntegratorKind::Normals, 4, 4));
    for (const Vec3f& p : image.pixels) EXPECT_EQ(p, Vec3f(0.0f));
}

TEST(RenderAo, OpenPlaneIsFullyUnoccluded) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {100, 0, 0}, {0, 100, 0}, t.add_material(diffuse(Vec3f(0.5f))));
    t.finish();
    RenderOptions o = options_for(IntegratorKind::AmbientOcclusion);
    o.ao_radius = 5.0f;
    o.spp = 2;
    Image image = t.render_with(looking_at({0, -2, 5}, {0, 0, 0}), o);
    for (const Vec3f& p : image.pixels) EXPECT_EQ(p, Vec3f(1.0f));
}

TEST(RenderAo, InsideAClosedBoxEverythingIsOccluded) {
    TestScene t;
    t.add_box(Vec3f(0.0f), 1.0f, t.add_material(diffuse(Vec3f(0.5f))));
    t.finish();
    RenderOptions o = options_for(IntegratorKind::AmbientOcclusion);
    o.ao_radius = 10.0f;
    Image image = t.render_with(looking_at({0.1f, 0.2f, 0.5f}, {0, 0, -1}, 90.0f), o);
    for (const Vec3f& p : image.pixels) EXPECT_EQ(p, Vec3f(0.0f));
    // A radius shorter than the distance to the walls sees no occluder in
    // most directions: the value must rise (the test can fail).
    o.ao_radius = 0.05f;
    Image near = t.render_with(looking_at({0.1f, 0.2f, 0.5f}, {0, 0, -1}, 90.0f), o);
    EXPECT_GT(near.at(4, 4).x, 0.5f);
}

// A small Cornell-like box exercising every Whitted feature.
TestScene feature_scene() {
    TestScene t;
    uint32_t white = t.add_material(diffuse(Vec3f(0.7f)));
    uint32_t red = t.add_material(diffuse(Vec3f(0.7f, 0.1f, 0.1f)));
    uint32_t light = t.add_material(emitter(Vec3f(8.0f)));
    Material mirror;
    mirror.base_color = Vec3f(0.9f);
    mirror.metallic = 1.0f;
    mirror.roughness = 0.0f;
    Material glass;
    glass.base_color = Vec3f(1.0f);
    glass.transmission = 1.0f;
    glass.ior = 1.5f;
    t.add_quad({0, 0, 0}, {2, 0, 0}, {0, 2, 0}, white);          // floor, facing +z
    t.add_quad({0, 2, 1}, {2, 0, 0}, {0, 0, 1}, red);            // back wall
    t.add_quad({0, 0, 1.99f}, {0.4f, 0, 0}, {0, -0.4f, 0}, light);  // ceiling light facing -z
    t.add_box({-0.6f, 0.4f, 0.4f}, 0.3f, t.add_material(mirror));
    t.add_box({0.6f, -0.2f, 0.4f}, 0.3f, t.add_material(glass));
    Light point;
    point.position = {1.0f, -1.0f, 1.5f};
    point.intensity = 0.5f;
    t.scene.lights.push_back(point);
    t.finish(Structure::Bvh);
    return t;
}

TEST(RenderWhitted, IdenticalWhateverTheThreadCountButSeedMatters) {
    TestScene t = feature_scene();
    Camera camera = looking_at({0, -4, 1.2f}, {0, 0, 0.6f}, 50.0f);
    RenderOptions o = options_for(IntegratorKind::Whitted, 40, 30);  // several 16x16 tiles, ragged edges
    o.spp = 3;
    o.threads = 1;
    Image one = t.render_with(camera, o);
    o.threads = 2;
    Image two = t.render_with(camera, o);
    ASSERT_EQ(one.pixels.size(), two.pixels.size());
    for (size_t i = 0; i < one.pixels.size(); ++i) ASSERT_EQ(one.pixels[i], two.pixels[i]) << "pixel " << i;

    o.seed = 7;
    Image reseeded = t.render_with(camera, o);
    size_t differing = 0;
    for (size_t i = 0; i < one.pixels.size(); ++i) differing += !(one.pixels[i] == reseeded.pixels[i]);
    EXPECT_GT(differing, one.pixels.size() / 10);
}

TEST(RenderWhitted, DiffusePlaneUnderPointLightMatchesLambert) {
    TestScene t;
    const float albedo = 0.5f;
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(diffuse(Vec3f(albedo))));
    Light light;
    light.position = {0.3f, -0.2f, 2.0f};
    light.color = {1.0f, 0.5f, 0.25f};
    light.intensity = 4.0f;
    t.scene.lights.push_back(light);
    t.finish();
    Camera camera = looking_at({0, 0, 5}, {0, 0, 0});
    const int n = 9;
    Image image = t.render_with(camera, options_for(IntegratorKind::Whitted, n, n));
    for (int y = 0; y < n; y += 2) {
        for (int x = 0; x < n; x += 2) {
            Vec3f p = hit_on_ground(camera, x, y, n, n);
            Vec3f to_light = light.position - p;
            float d2 = dot(to_light, to_light);
            float cos_theta = to_light.z / std::sqrt(d2);
            Vec3f expected = light.color * (albedo / kPiF * light.intensity * cos_theta / d2);
            expect_color_near(image.at(x, y), expected, 0.01f, "lambert");
        }
    }
}

TEST(RenderWhitted, DirectionalAndSpotLights) {
    TestScene t;
    const float albedo = 0.5f;
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(diffuse(Vec3f(albedo))));
    Light sun;
    sun.type = LightType::Directional;
    sun.direction = {0.6f, 0.0f, -0.8f};
    sun.intensity = 2.0f;
    t.scene.lights.push_back(sun);
    t.finish();
    Camera camera = looking_at({0, 0, 5}, {0, 0, 0});
    Image image = t.render_with(camera, options_for(IntegratorKind::Whitted, 5, 5));
    for (const Vec3f& p : image.pixels) expect_color_near(p, Vec3f(albedo / kPiF * 2.0f * 0.8f), 0.001f, "sun");

    TestScene s;
    s.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, s.add_material(diffuse(Vec3f(albedo))));
    Light spot;
    spot.type = LightType::Spot;
    spot.position = {0, 0, 2};
    spot.direction = {0, 0, -1};
    spot.intensity = 4.0f;
    spot.inner_cone_radians = 10.0f * kPiF / 180.0f;
    spot.outer_cone_radians = 20.0f * kPiF / 180.0f;
    s.scene.lights.push_back(spot);
    s.finish();
    const int n = 9;
    Image lit = s.render_with(camera, options_for(IntegratorKind::Whitted, n, n));
    // Centre: inside the inner cone, a point light's value; corner: outside the outer cone, dark.
    expect_color_near(lit.at(4, 4), Vec3f(albedo / kPiF * 4.0f / 4.0f), 0.01f, "spot centre");
    Vec3f corner = hit_on_ground(camera, 0, 0, n, n);
    ASSERT_GT(std::atan(length(Vec3f(corner.x, corner.y, 0.0f)) / 2.0f), spot.outer_cone_radians);
    EXPECT_EQ(lit.at(0, 0), Vec3f(0.0f));
}

TEST(RenderWhitted, OccluderCastsAHardShadow) {
    for (bool blocked : {false, true}) {
        TestScene t;
        uint32_t white = t.add_material(diffuse(Vec3f(0.5f)));
        t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, white);
        if (blocked) t.add_quad({0, 0, 1}, {0.5f, 0, 0}, {0, 0.5f, 0}, white);
        Light light;
        light.position = {0, 0, 2};
        t.scene.lights.push_back(light);
        t.finish();
        // The camera looks past the blocker at the point under it.
        Image image = t.render_with(looking_at({3, 0, 3}, {0, 0, 0}), options_for(IntegratorKind::Whitted, 5, 5));
        if (blocked) EXPECT_EQ(image.at(2, 2), Vec3f(0.0f));
        else EXPECT_GT(image.at(2, 2).x, 0.01f);
    }
}

TEST(RenderWhitted, SmallAreaLightMatchesTheSolidAngleEstimate) {
    TestScene t;
    const float albedo = 0.6f, radiance = 100.0f, half = 0.05f;
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(diffuse(Vec3f(albedo))));
    t.add_quad({0, 0, 1}, {half, 0, 0}, {0, -half, 0}, t.add_material(emitter(Vec3f(radiance))));  // faces -z
    t.finish();
    // One sample at the pixel centre: a jittered footprint would average the falloff.
    Image image = t.render_with(looking_at({0, -3, 3}, {0, 0, 0}), options_for(IntegratorKind::Whitted, 5, 5));
    // E = L * A * cos * cos' / d^2 with both cosines ~1 for a light this small.
    float area = 4.0f * half * half;
    float expected = albedo / kPiF * radiance * area;
    EXPECT_NEAR(image.at(2, 2).x, expected, 0.01f * expected);
}

TEST(RenderWhitted, MirrorShowsWhatItFacesTintedByItsColor) {
    TestScene t;
    const Vec3f tint(0.9f, 0.8f, 0.7f), sky(1.0f, 0.5f, 0.25f);
    add_mirror_facing_sky(t, tint, sky);
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}), options_for(IntegratorKind::Whitted, 5, 5));
    for (const Vec3f& p : image.pixels) expect_color_near(p, sky * tint, 1e-4f, "mirror");
}

TEST(RenderWhitted, GlassSlabAtNormalIncidenceTransmitsFresnelSquared) {
    TestScene t;
    Material glass;
    glass.base_color = Vec3f(1.0f);
    glass.transmission = 1.0f;
    glass.ior = 1.5f;
    uint32_t g = t.add_material(glass);
    t.add_quad({0, 0, 0}, {10, 0, 0}, {0, 10, 0}, g);       // top face, normal +z
    t.add_quad({0, 0, -0.1f}, {0, 10, 0}, {10, 0, 0}, g);   // bottom face, normal -z
    t.add_quad({0, 0, -5}, {20, 0, 0}, {0, 20, 0}, t.add_material(emitter(Vec3f(1.0f))));
    t.finish();
    RenderOptions o = options_for(IntegratorKind::Whitted, 3, 3);
    o.refraction_depth = 8;
    o.reflection_depth = 8;
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}, 1.0f), o);
    // F = ((n-1)/(n+1))^2 = 0.04 per face; the inter-reflections between the
    // faces sum the series (1-F)^2 (1 + F^2 + F^4 ...) = (1-F)^2 / (1-F^2).
    const float f = 0.04f;
    EXPECT_NEAR(image.at(1, 1).x, (1 - f) * (1 - f) / (1 - f * f), 2e-3f);
    o.refraction_depth = 1;  // enters the glass but cannot leave it
    Image shallow = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}, 1.0f), o);
    EXPECT_LT(shallow.at(1, 1).x, 0.01f);
}

TEST(RenderWhitted, FresnelReflectanceAndTotalInternalReflection) {
    EXPECT_NEAR(fresnel_dielectric(1.0f, 1.0f / 1.5f), 0.04f, 1e-6f);
    EXPECT_NEAR(fresnel_dielectric(1.0f, 1.5f), 0.04f, 1e-6f);
    EXPECT_EQ(fresnel_dielectric(std::cos(60.0f * kPiF / 180.0f), 1.5f), 1.0f);  // beyond the critical angle
    EXPECT_NEAR(fresnel_dielectric(1e-4f, 1.0f / 1.5f), 1.0f, 1e-3f);         // grazing
    Vec3f out;
    EXPECT_FALSE(refract(normalize(Vec3f(1, 0, -0.2f)), Vec3f(0, 0, 1), 1.5f, out));
    ASSERT_TRUE(refract(normalize(Vec3f(1, 0, -1)), Vec3f(0, 0, 1), 1.0f / 1.5f, out));
    EXPECT_NEAR(out.x, std::sin(45.0f * kPiF / 180.0f) / 1.5f, 1e-5f);  // Snell
}

TEST(RenderWhitted, AlphaMaskCutsOutButOpaqueAlphaDoesNot) {
    for (float alpha : {0.2f, 0.8f}) {
        TestScene t;
        Material cutout = emitter(Vec3f(1, 0, 0));
        cutout.alpha = alpha;
        cutout.alpha_mode = AlphaMode::Mask;
        t.add_quad({0, 0, 1}, {10, 0, 0}, {0, 10, 0}, t.add_material(cutout));
        t.add_quad({0, 0, 0}, {10, 0, 0}, {0, 10, 0}, t.add_material(emitter(Vec3f(0, 1, 0))));
        t.finish();
        Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}), options_for(IntegratorKind::Whitted, 3, 3));
        Vec3f expected = alpha < 0.5f ? Vec3f(0, 1, 0) : Vec3f(1, 0, 0);
        EXPECT_EQ(image.at(1, 1), expected) << "alpha " << alpha;
    }
}

TEST(Render, ProgressIsReportedUpToCompletion) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {1, 0, 0}, {0, 1, 0}, t.add_material(diffuse(Vec3f(0.5f))));
    t.finish();
    std::vector<double> reported;
    RenderOptions o = options_for(IntegratorKind::Normals, 50, 40);  // 4 x 3 tiles
    (void)render(*t.world, looking_at({0, 0, 5}, {0, 0, 0}), o,
                 [&](double f) { reported.push_back(f); });
    ASSERT_EQ(reported.size(), 12u);
    for (size_t i = 1; i < reported.size(); ++i) EXPECT_GT(reported[i], reported[i - 1]);
    EXPECT_DOUBLE_EQ(reported.back(), 1.0);
}

TEST(Render, InvalidOptionsAndIntegratorNamesAreErrors) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {1, 0, 0}, {0, 1, 0}, t.add_material(diffuse(Vec3f(0.5f))));
    t.finish();
    Camera camera = looking_at({0, 0, 5}, {0, 0, 0});
    auto attempt = [&](auto change) {
        RenderOptions o = options_for(IntegratorKind::Normals, 4, 4);
        change(o);
        return t.render_with(camera, o);
    };
    EXPECT_THROW(attempt([](RenderOptions& o) { o.width = 0; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.height = 70000; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.width = 65536; o.height = 65536; }), Error);  // 48 GiB
    EXPECT_THROW(attempt([](RenderOptions& o) { o.spp = 0; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.max_depth = -1; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.rr_depth = -1; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.reflection_depth = 31; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.refraction_depth = -1; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.time_budget_s = -1.0; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.max_sample_value = NAN; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.ao_samples = 0; }), Error);
    EXPECT_THROW(attempt([](RenderOptions& o) { o.ao_radius = NAN; }), Error);

    for (IntegratorKind k :
         {IntegratorKind::Normals, IntegratorKind::AmbientOcclusion, IntegratorKind::Whitted, IntegratorKind::Path})
        EXPECT_EQ(parse_integrator(integrator_name(k)), k);
    EXPECT_EQ(integrator_name(IntegratorKind::AmbientOcclusion), "ao");
    EXPECT_THROW((void)parse_integrator("bidir"), Error);
    for (LightSampling l : {LightSampling::Mis, LightSampling::Nee, LightSampling::Bsdf})
        EXPECT_EQ(parse_light_sampling(to_string(l)), l);
    EXPECT_THROW((void)parse_light_sampling("mixed"), Error);
    for (WhittedShading w : {WhittedShading::Lambert, WhittedShading::Phong, WhittedShading::Blinn})
        EXPECT_EQ(parse_whitted_shading(to_string(w)), w);
    EXPECT_THROW((void)parse_whitted_shading("gouraud"), Error);
}


// A GL pixel buffer is registered with a CUDA device: the CPU device, and a
// CUDA device this process cannot use, are one-line errors.
TEST(Render, GlPixelBufferNeedsAUsableCudaDevice) {
    EXPECT_THROW((void)register_gl_pixel_buffer(Device{}, 1u), Error);
    if (list_cuda_devices().devices.empty())
        EXPECT_THROW((void)register_gl_pixel_buffer(parse_device("cuda:0"), 1u), Error);
}

}  // namespace
}  // namespace rf
