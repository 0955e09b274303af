// The path tracer against answers known in closed form: furnaces (a surface
// inside a uniform environment, or a closed box of emitting walls), a mirror,
// a glass sphere, a Lambert plane under a point light; the three
// light-sampling strategies against each other; determinism; the
// progressive renderer's passes, budgets and AOVs.
#include <gtest/gtest.h>

#include <atomic>

#include <cmath>
#include <cstdio>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/render/render.h"
#include "render_test_scene.h"

namespace rf {
namespace {

// Mean of the pixels selected by `use` and the standard error of that mean,
// treating each pixel as an independent estimate (which it is: every pixel
// has its own random streams).
struct MeanEstimate {
    double mean = 0.0, standard_error = 0.0;
    size_t count = 0;
};

template <class Use>
MeanEstimate mean_of(const Image& image, int channel, Use use) {
    MeanEstimate e;
    double sum = 0.0, sum2 = 0.0;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) {
            if (!use(x, y)) continue;
            double v = image.at(x, y)[channel];
            sum += v;
            sum2 += v * v;
            ++e.count;
        }
    if (e.count < 2) return e;
    e.mean = sum / double(e.count);
    double variance = std::max(0.0, (sum2 - sum * e.mean) / double(e.count - 1));
    e.standard_error = std::sqrt(variance / double(e.count));
    return e;
}

auto everywhere = [](int, int) { return true; };

Material lambert(float albedo) {
    Material m;
    m.base_color = Vec3f(albedo);
    m.roughness = 1.0f;
    m.specular = 0.0f;  // no specular layer: a pure Lambert surface
    m.ior = 1.0f;       // (the same for a BSDF without the specular factor)
    return m;
}

RenderOptions path_options(int w, int h, int spp) {
    RenderOptions o = options_for(IntegratorKind::Path, w, h);
    o.spp = spp;
    o.max_depth = 16;
    return o;
}

// A sphere of radius 1 at the origin in a uniform environment of radiance 1.
TestScene furnace_sphere(const Material& m) {
    TestScene t;
    t.add_sphere(Vec3f(0.0f), 1.0f, t.add_material(m));
    t.scene.environment.color = Vec3f(1.0f);
    t.finish(Structure::Bvh);
    return t;
}

TEST(PathTracer, WhiteFurnaceDiffuseSphereRendersOne) {
    TestScene t = furnace_sphere(lambert(1.0f));
    Image image = t.render_with(looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), path_options(24, 24, 32));
    for (int c = 0; c < 3; ++c) {
        MeanEstimate e = mean_of(image, c, everywhere);
        EXPECT_NEAR(e.mean, 1.0, 5.0 * e.standard_error + 2e-3) << "channel " << c;
    }
    MeanEstimate e = mean_of(image, 0, everywhere);
    EXPECT_GT(e.standard_error, 0.0);  // the sphere's pixels are Monte Carlo estimates
}

TEST(PathTracer, DarkerAlbedoIsNeverBrighterThanTheEnvironment) {
    TestScene t = furnace_sphere(lambert(0.5f));
    Image image = t.render_with(looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), path_options(24, 24, 32));
    // Centre pixels see the sphere: a convex Lambert sphere reflects exactly
    // its albedo times the environment.
    auto centre = [](int x, int y) { return std::abs(x - 12) < 5 && std::abs(y - 12) < 5; };
    MeanEstimate e = mean_of(image, 1, centre);
    EXPECT_NEAR(e.mean, 0.5, 5.0 * e.standard_error + 2e-3);
    MeanEstimate whole = mean_of(image, 1, everywhere);
    EXPECT_LT(whole.mean, 1.0);  // background pixels are exactly 1, the sphere's about 0.5
}

TEST(PathTracer, SmoothGlassSphereIsInvisibleInAFurnace) {
    Material glass;
    glass.base_color = Vec3f(1.0f);
    glass.transmission = 1.0f;
    glass.roughness = 0.0f;
    glass.ior = 1.5f;
    TestScene t = furnace_sphere(glass);
    RenderOptions o = path_options(16, 16, 8);
    o.max_depth = 64;
    o.rr_depth = 64;
    Image image = t.render_with(looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), o);
    // Lossless: every path leaves with throughput 1 unless it is cut at
    // max_depth inside the sphere (total internal reflection loops are rare).
    for (const Vec3f& p : image.pixels) {
        EXPECT_LE(p.x, 1.0f + 1e-4f);
        EXPECT_GE(p.x, 0.97f);
    }
}

// With the multiple-scattering compensation (bsdf.h, Turquin 2019) a white
// rough conductor and rough clear glass lose no energy: the sphere renders
// the environment's 1. Tolerance: 4 standard errors of the image's own
// estimate plus 1% (the tables' interpolation error; paths cut at max_depth
// inside the glass). Printed values are quoted in docs/rendering.md.
TEST(PathTracer, RoughGlassAndMetalsConserveEnergyInAFurnace) {
    for (float roughness : {0.1f, 0.25f, 0.5f, 0.75f, 1.0f}) {
        for (int kind = 0; kind < 2; ++kind) {
            Material m;
            m.base_color = Vec3f(1.0f);
            m.roughness = roughness;
            if (kind == 0) m.transmission = 1.0f;
            else m.metallic = 1.0f;
            TestScene t = furnace_sphere(m);
            RenderOptions o = path_options(32, 32, 32);
            o.max_depth = 32;
            Image image = t.render_with(looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), o);
            MeanEstimate e = mean_of(image, 0, everywhere);
            std::printf("furnace %-9s roughness %.2f: %.4f +- %.4f\n", kind == 0 ? "glass" : "conductor", roughness,
                        e.mean, e.standard_error);
            EXPECT_NEAR(e.mean, 1.0, 4.0 * e.standard_error + 0.01)
                << (kind == 0 ? "glass" : "conductor") << " roughness " << roughness;
        }
    }
}

// Inside a closed box whose walls all emit Le and reflect with albedo rho,
// radiance is Le / (1 - rho) everywhere: every bounce, every light sample
// and Russian roulette take part.
TEST(PathTracer, ClosedEmittingBoxReachesTheInfiniteBounceLimit) {
    for (int strategy = 0; strategy < 3; ++strategy) {
        TestScene t;
        Material wall = lambert(0.5f);
        wall.emission = Vec3f(1.0f);
        uint32_t m = t.add_material(wall);
        Vec3f x(1, 0, 0), y(0, 1, 0), z(0, 0, 1);
        // Normals point inwards.
        t.add_quad(z, y, x, m);
        t.add_quad(-z, x, y, m);
        t.add_quad(x, z, y, m);
        t.add_quad(-x, y, z, m);
        t.add_quad(y, x, z, m);
        t.add_quad(-y, z, x, m);
        t.finish(Structure::Bvh);
        RenderOptions o = path_options(12, 12, 16);
        o.max_depth = 64;
        o.rr_depth = 1;
        o.light_sampling = LightSampling(strategy);
        Image image = t.render_with(looking_at({0, 0, 0.5f}, {0, 0, -1}, 60.0f), o);
        MeanEstimate e = mean_of(image, 0, everywhere);
        EXPECT_NEAR(e.mean, 2.0, 5.0 * e.standard_error + 5e-3) << "strategy " << strategy;
    }
}

TEST(PathTracer, MirrorShowsWhatItFacesTintedByItsColor) {
    TestScene t;
    const Vec3f tint(0.9f, 0.8f, 0.7f), sky(1.0f, 0.5f, 0.25f);
    add_mirror_facing_sky(t, tint, sky);
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}), path_options(5, 5, 4));
    for (const Vec3f& p : image.pixels)
        for (int c = 0; c < 3; ++c) EXPECT_NEAR(p[c], sky[c] * tint[c], 2e-3f);
}

TEST(PathTracer, LambertPlaneUnderPointLight) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(lambert(0.5f)));
    Light light;
    light.position = {0, 0, 2};
    light.intensity = 8.0f;
    t.scene.lights.push_back(light);
    t.finish();
    RenderOptions o = path_options(3, 3, 4);
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}, 0.5f), o);
    // L = albedo / pi * I cos / d^2 at the point below the light.
    const float expected = 0.5f / kPiF * 8.0f / 4.0f;
    EXPECT_NEAR(image.at(1, 1).x, expected, 1e-3f * expected * 10.0f);
}

// Material::ambient is Whitted's k_a * I_a: with no light at all a Whitted
// render of a Lambert plane shows exactly its ambient radiance; the
// physically based path tracer adds no such term.
TEST(Renderer, WhittedAddsTheAmbientTermThePathTracerDoesNot) {
    TestScene t;
    Material floor = lambert(0.5f);
    floor.ambient = Vec3f(0.25f, 0.5f, 1.0f);
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(floor));
    t.finish();
    RenderOptions whitted = options_for(IntegratorKind::Whitted, 3, 3);
    Image image = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}, 0.5f), whitted);
    for (const Vec3f& p : image.pixels) {
        EXPECT_FLOAT_EQ(p.x, 0.25f);
        EXPECT_FLOAT_EQ(p.y, 0.5f);
        EXPECT_FLOAT_EQ(p.z, 1.0f);
    }
    Image path = t.render_with(looking_at({0, 0, 5}, {0, 0, 0}, 0.5f), path_options(3, 3, 2));
    for (const Vec3f& p : path.pixels) EXPECT_EQ(max_component(p), 0.0f);
}

// A diffuse floor and a glossy sphere lit by a quad light and a dim
// environment: light sampling only, BSDF sampling only and their MIS
// combination estimate the same image.
TEST(PathTracer, NeeBsdfAndMisEstimatesAgree) {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {3, 0, 0}, {0, 3, 0}, t.add_material(lambert(0.7f)));
    Material glossy;
    glossy.base_color = Vec3f(0.9f, 0.6f, 0.3f);
    glossy.metallic = 1.0f;
    glossy.roughness = 0.35f;
    t.add_sphere({0, 0, 0.6f}, 0.6f, t.add_material(glossy), 32);
    t.add_quad({0.5f, 0.5f, 2.5f}, {0, 0.6f, 0}, {0.6f, 0, 0}, t.add_material(emitter(Vec3f(6.0f))));  // faces -z
    t.scene.environment.color = Vec3f(0.2f);
    t.finish(Structure::Bvh);
    Camera camera = looking_at({0, -4, 2.5f}, {0, 0, 0.4f}, 45.0f);
    std::vector<Image> images;
    for (LightSampling s : {LightSampling::Mis, LightSampling::Nee, LightSampling::Bsdf}) {
        RenderOptions o = path_options(32, 24, 24);
        o.max_depth = 4;
        o.light_sampling = s;
        images.push_back(t.render_with(camera, o));
    }
    for (int a = 0; a < 3; ++a) {
        for (int b = a + 1; b < 3; ++b) {
            Image difference(images[a].width, images[a].height);
            for (size_t i = 0; i < difference.pixels.size(); ++i)
                difference.pixels[i] = images[a].pixels[i] - images[b].pixels[i];
            for (int c = 0; c < 3; ++c) {
                MeanEstimate e = mean_of(difference, c, everywhere);
                EXPECT_NEAR(e.mean, 0.0, 5.0 * e.standard_error) << "strategies " << a << " vs " << b << " channel " << c;
            }
        }
    }
    EXPECT_GT(mean_of(images[0], 0, everywhere).mean, 0.05);  // the scene is lit
}

// An emitter facing away from a floor and from the camera: one-sided, it
// lights nothing and is black from behind for every strategy (light samples,
// BSDF hits, the camera ray) and for Whitted; two-sided, it lights the floor
// and the strategies agree.
TEST(PathTracer, OneSidedEmittersAreDarkFromBehindForEveryStrategy) {
    for (bool two_sided : {false, true}) {
        TestScene t;
        t.add_quad(Vec3f(0.0f), {3, 0, 0}, {0, 3, 0}, t.add_material(lambert(0.7f)));  // faces +z
        Material light = emitter(Vec3f(6.0f));
        light.two_sided_emission = two_sided;
        t.add_quad({0, 0, 1.0f}, {0.6f, 0, 0}, {0, 0.6f, 0}, t.add_material(light));  // faces +z: away
        t.finish(Structure::Bvh);
        const Camera camera = looking_at({0, -4, 0.6f}, {0, 0, 0.3f}, 50.0f);  // below the light
        std::vector<Image> images;
        for (LightSampling s : {LightSampling::Mis, LightSampling::Nee, LightSampling::Bsdf}) {
            RenderOptions o = path_options(24, 16, 16);
            o.max_depth = 3;
            o.light_sampling = s;
            images.push_back(t.render_with(camera, o));
        }
        RenderOptions whitted = options_for(IntegratorKind::Whitted, 24, 16);
        whitted.spp = 4;
        images.push_back(t.render_with(camera, whitted));
        for (size_t i = 0; i < images.size(); ++i) {
            const double mean = mean_of(images[i], 0, everywhere).mean;
            if (two_sided) EXPECT_GT(mean, 0.02) << "image " << i;
            else EXPECT_EQ(mean, 0.0) << "image " << i;
        }
        if (!two_sided) continue;
        for (int b = 1; b < 3; ++b) {
            Image difference(images[0].width, images[0].height);
            for (size_t i = 0; i < difference.pixels.size(); ++i)
                difference.pixels[i] = images[0].pixels[i] - images[size_t(b)].pixels[i];
            MeanEstimate e = mean_of(difference, 0, everywhere);
            EXPECT_NEAR(e.mean, 0.0, 5.0 * e.standard_error) << "MIS vs strategy " << b;
        }
    }
}

TEST(PathTracer, IdenticalWhateverTheThreadCountButSeedMatters) {
    TestScene t = furnace_sphere(lambert(0.7f));
    RenderOptions o = path_options(20, 20, 3);
    Camera camera = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f);
    o.threads = 1;
    Image one = t.render_with(camera, o);
    o.threads = 2;
    Image two = t.render_with(camera, o);
    EXPECT_EQ(one.pixels, two.pixels);
    o.seed = 7;
    Image other = t.render_with(camera, o);
    EXPECT_NE(one.pixels, other.pixels);
}

TEST(Renderer, PassesAccumulateAndCallbacksCanStop) {
    TestScene t = furnace_sphere(lambert(0.7f));
    Camera camera = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f);
    RenderOptions o = path_options(16, 16, 8);
    const auto renderer = make_renderer(*t.world, camera, o);
    EXPECT_EQ(renderer->passes(), 0);
    EXPECT_EQ(renderer->device(), Device{});
    int calls = 0;
    render_progressive(*renderer, [&](const Renderer& r) {
        ++calls;
        EXPECT_EQ(r.passes(), calls);
        EXPECT_EQ(r.last_pass().closest_rays, r.stats().closest_rays / uint64_t(calls));
        return calls < 3;
    });
    EXPECT_EQ(renderer->passes(), 3);
    EXPECT_EQ(renderer->stats().samples, 3u * 16u * 16u);
    EXPECT_GT(renderer->stats().closest_rays, renderer->stats().samples);
    EXPECT_GT(renderer->last_pass().pass_ms, 0.0);
    // The mean of three passes equals three passes rendered in one go.
    o.spp = 3;
    Image direct = render(*t.world, camera, o);
    EXPECT_EQ(renderer->image().pixels, direct.pixels);
}

TEST(Renderer, TimeBudgetStopsEarly) {
    TestScene t = furnace_sphere(lambert(0.7f));
    RenderOptions o = path_options(8, 8, 1 << 20);
    o.time_budget_s = 0.05;
    const auto renderer = make_renderer(*t.world, looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), o);
    render_progressive(*renderer);
    EXPECT_GE(renderer->passes(), 1);
    EXPECT_LT(renderer->passes(), 1 << 20);
}

TEST(Renderer, AovsDescribeTheFirstHit) {
    TestScene t;
    Material m = lambert(0.25f);
    m.base_color = Vec3f(0.25f, 0.5f, 0.75f);
    t.add_quad(Vec3f(0.0f), {10, 0, 0}, {0, 10, 0}, t.add_material(m));
    t.finish();
    for (IntegratorKind k : {IntegratorKind::Path, IntegratorKind::Whitted}) {
        RenderOptions o = path_options(3, 3, 2);
        o.integrator = k;
        o.aovs = true;
        const auto renderer =
            make_renderer(*t.world, looking_at({0, 0, 5}, {0, 0, 0}, 1.0f), o);
        render_progressive(*renderer);
        const Vec3f albedo = renderer->albedo().at(1, 1), normal = renderer->normal().at(1, 1);
        EXPECT_NEAR(albedo.x, 0.25f, 1e-4f);
        EXPECT_NEAR(albedo.z, 0.75f, 1e-4f);
        EXPECT_NEAR(normal.z, 1.0f, 1e-4f);
        EXPECT_NEAR(renderer->depth().at(1, 1).x, 5.0f, 1e-3f);
    }
    RenderOptions o = path_options(3, 3, 1);
    const auto plain = make_renderer(*t.world, looking_at({0, 0, 5}, {0, 0, 0}, 1.0f), o);
    plain->render_pass();
    EXPECT_EQ(plain->albedo().width, 0);  // AOVs off: nothing accumulated
}

// A camera move restarts accumulation: afterwards the renderer draws what a
// fresh renderer at the new camera draws, to the bit.
TEST(Renderer, CameraChangeRestartsAccumulation) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const Camera near = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), far = looking_at({1, 1, 6}, {0, 0, 0}, 40.0f);
    RenderOptions o = path_options(12, 10, 2);
    const auto renderer = make_renderer(*t.world, near, o);
    render_progressive(*renderer);
    const Image before = renderer->image();
    renderer->set_camera(far);
    EXPECT_EQ(renderer->passes(), 0);
    EXPECT_EQ(renderer->stats().samples, 0u);
    render_progressive(*renderer);
    EXPECT_EQ(renderer->image().pixels, render(*t.world, far, o).pixels);
    EXPECT_NE(renderer->image().pixels, before.pixels);
}

// New options (another integrator and resolution) restart with new films.
TEST(Renderer, OptionChangesRestartWithNewFilms) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const Camera camera = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f);
    const auto renderer = make_renderer(*t.world, camera, path_options(8, 8, 2));
    render_progressive(*renderer);
    RenderOptions w = path_options(10, 6, 1);
    w.integrator = IntegratorKind::Whitted;
    w.aovs = true;
    renderer->set_options(w);
    EXPECT_EQ(renderer->passes(), 0);
    render_progressive(*renderer);
    EXPECT_EQ(renderer->image().width, 10);
    EXPECT_EQ(renderer->albedo().height, 6);
    EXPECT_EQ(renderer->image().pixels, render(*t.world, camera, w).pixels);
    RenderOptions bad = w;
    bad.width = 0;
    EXPECT_THROW(renderer->set_options(bad), Error);
}

// A material changed in the world: the renderer, told nothing, rebuilds its
// shading tables at its next pass, restarts, and renders the changed scene
// as a fresh renderer would.
TEST(Renderer, FollowsMaterialChangesOfItsWorld) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const Camera camera = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f);
    const RenderOptions o = path_options(8, 8, 2);
    const auto renderer = make_renderer(*t.world, camera, o);
    render_progressive(*renderer);
    const Image grey = renderer->image();
    for (Material& m : t.world->scene().materials) m.base_color = Vec3f(0.2f, 0.9f, 0.3f);
    t.world->materials_changed();
    EXPECT_EQ(renderer->passes(), 0);  // behind its world: restarted (its tables follow at the next pass)
    EXPECT_EQ(renderer->stats().samples, 0u);
    ASSERT_TRUE(renderer->render_pass());
    EXPECT_EQ(renderer->passes(), 1);  // one pass of the new scene
    render_progressive(*renderer);
    EXPECT_NE(renderer->image().pixels, grey.pixels);
    EXPECT_EQ(renderer->image().pixels, render(*t.world, camera, o).pixels);
    // A material index out of range is refused before any renderer sees it.
    t.world->scene().materials[0].base_color_texture = 7;
    EXPECT_THROW(t.world->materials_changed(), Error);
    t.world->scene().materials[0].base_color_texture = kNoTexture;
}

// A pass stopped by its cancel flag adds nothing: accumulation restarts, and
// the next passes draw what a fresh renderer draws.
TEST(Renderer, CancelledPassRestartsAccumulation) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const Camera camera = looking_at({0, 0, 3}, {0, 0, 0}, 30.0f);
    for (bool wavefront : {false, true}) {
        RenderOptions o = path_options(48, 40, 2);  // 9 tiles, one thread: the flag is seen between them
        o.threads = 1;
        o.wavefront = wavefront;
        const auto renderer = make_renderer(*t.world, camera, o);
        ASSERT_TRUE(renderer->render_pass());
        std::atomic<bool> cancel{true};
        EXPECT_FALSE(renderer->render_pass({}, &cancel));  // set before the pass: nothing runs
        EXPECT_EQ(renderer->passes(), 0);
        EXPECT_EQ(renderer->stats().samples, 0u);
        if (!wavefront) {
            cancel = false;
            int calls = 0;
            const bool finished = renderer->render_pass([&](double) { cancel = ++calls == 1; }, &cancel);
            EXPECT_FALSE(finished);  // set after the first tile
            EXPECT_LT(calls, 9);
            EXPECT_EQ(renderer->passes(), 0);
            for (const Vec3f& p : renderer->image().pixels) ASSERT_EQ(p, Vec3f(0.0f));
        }
        cancel = false;
        EXPECT_TRUE(renderer->render_pass({}, &cancel));
        EXPECT_TRUE(renderer->render_pass({}, &cancel));
        EXPECT_EQ(renderer->image().pixels, render(*t.world, camera, o).pixels);
    }
}

// The display image holds, for every curve and exposure, the 8-bit sRGB code
// a PNG of image() holds, with opaque alpha.
TEST(Renderer, DisplayImageIsTheToneMappedMean) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const auto renderer =
        make_renderer(*t.world, looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), path_options(12, 10, 2));
    const auto display = renderer->make_display_image();
    renderer->update_display(*display, {});
    EXPECT_EQ(display->width(), 12);  // black before the first pass
    for (size_t i = 0; i < 12 * 10; ++i) EXPECT_EQ(display->host_pixels()[4 * i], 0);
    render_progressive(*renderer);
    const Image mean = renderer->image();
    for (ToneCurve curve : {ToneCurve::Clamp, ToneCurve::Reinhard, ToneCurve::Aces})
        for (float exposure : {0.5f, 1.0f, 3.0f}) {
            const ToneMapping tone{exposure, curve};
            renderer->update_display(*display, tone);
            ASSERT_EQ(display->device(), Device{});
            ASSERT_EQ(display->device_pixels(), nullptr);
            const std::vector<uint8_t> pixels = display->download();
            ASSERT_EQ(pixels.size(), mean.pixels.size() * 4);
            for (size_t i = 0; i < mean.pixels.size(); ++i) {
                uint8_t expected[3];
                tone_map_srgb8(mean.pixels[i], tone, expected);
                for (int k = 0; k < 3; ++k) ASSERT_EQ(pixels[4 * i + size_t(k)], expected[k]) << "pixel " << i;
                ASSERT_EQ(pixels[4 * i + 3], 255);
            }
        }
}

// A renderer runs where its world lives; a world on a device this process
// cannot use is refused when it is made, in one line.
TEST(Renderer, RunsWhereItsWorldLives) {
    TestScene t = furnace_sphere(lambert(0.7f));
    const auto renderer = make_renderer(*t.world, looking_at({0, 0, 3}, {0, 0, 0}, 30.0f), path_options(4, 4, 1));
    EXPECT_EQ(renderer->device(), t.world->device());
    WorldOptions nowhere;
    nowhere.device = parse_device("cuda:7");
    try {
        (void)make_world(t.scene, nowhere);
        if (!cuda_backend_built()) ADD_FAILURE() << "a CUDA world in a build without the backend";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
        EXPECT_NE(std::string(e.what()).find("cuda:7"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace rf
