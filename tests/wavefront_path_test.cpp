// The wavefront path tracer against the megakernel: the same stages
// (path_stages.h) scheduled queue by queue must give the same image, bit for
// bit, whatever the scene (opaque, cut-out and blended surfaces, environment
// light), the light-sampling strategy, the ray sorting, the thread count or
// the pass; and the ray sort key (Garanzha and Loop 2010) and the queue sort
// it drives.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <numeric>
#include <span>
#include <string>
#include <vector>

#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"
#include "backend/cpu/cpu_wavefront.h"
#include "math/random.h"
#include "render/integrators/path_stages.h"
#include "render/ray_sort_key.h"
#include "render_test_scene.h"

namespace rf {
namespace {

struct Films {
    Image color, albedo, normal, depth;
    RenderStats stats;
};

Films render_films(World& world, const Camera& camera, const RenderOptions& options) {
    const auto renderer = make_renderer(world, camera, options);
    render_progressive(*renderer);
    return {renderer->image(), renderer->albedo(), renderer->normal(), renderer->depth(), renderer->stats()};
}

// Bit-exact equality, reporting the first pixel that differs.
void expect_same_image(const Image& expected, const Image& actual, const std::string& what) {
    ASSERT_EQ(expected.width, actual.width) << what;
    ASSERT_EQ(expected.height, actual.height) << what;
    size_t differing = 0, first = 0;
    for (size_t i = 0; i < expected.pixels.size(); ++i) {
        if (expected.pixels[i] == actual.pixels[i]) continue;
        if (differing++ == 0) first = i;
    }
    EXPECT_EQ(differing, 0u) << what << ": first at pixel " << first << " expected (" << expected.pixels[first].x
                             << ", " << expected.pixels[first].y << ", " << expected.pixels[first].z << ") got ("
                             << actual.pixels[first].x << ", " << actual.pixels[first].y << ", "
                             << actual.pixels[first].z << ")";
}

struct WavefrontVariant {
    int threads;
    bool sort;
};
constexpr WavefrontVariant kEveryVariant[] = {{1, false}, {1, true}, {2, false}, {2, true}};

// Renders `options` as the megakernel, then as the wavefront in each variant
// (sorting off and on, 1 and 2 threads), and expects every film and the
// query counts to agree exactly.
void expect_wavefront_matches(World& world, const Camera& camera, RenderOptions options, const std::string& what,
                              std::span<const WavefrontVariant> variants = kEveryVariant) {
    options.integrator = IntegratorKind::Path;
    options.aovs = true;
    options.wavefront = false;
    const Films mega = render_films(world, camera, options);
    double mean = 0.0;
    for (const Vec3f& p : mega.color.pixels) mean += p.x + p.y + p.z;
    ASSERT_GT(mean, 0.0) << what << ": the scene must be lit for the comparison to mean something";
    for (const WavefrontVariant& v : variants) {
        RenderOptions w = options;
        w.wavefront = true;
        w.sort_rays = v.sort;
        w.threads = v.threads;
        const std::string label = what + (v.sort ? ", sorted" : ", unsorted") + ", threads " + std::to_string(v.threads);
        const Films wave = render_films(world, camera, w);
        expect_same_image(mega.color, wave.color, label + ": colour");
        expect_same_image(mega.albedo, wave.albedo, label + ": albedo");
        expect_same_image(mega.normal, wave.normal, label + ": normal");
        expect_same_image(mega.depth, wave.depth, label + ": depth");
        EXPECT_EQ(mega.stats.samples, wave.stats.samples) << label;
        EXPECT_EQ(mega.stats.closest_rays, wave.stats.closest_rays) << label;
        EXPECT_EQ(mega.stats.shadow_rays, wave.stats.shadow_rays) << label;
    }
}

// The default structure: BVH8, traced in packets by the batch API.
std::unique_ptr<World> load(const std::string& name) { return open_world(name); }

RenderOptions small_path_options(int w, int h, int passes) {
    RenderOptions o = options_for(IntegratorKind::Path, w, h);
    o.spp = passes;
    o.seed = 3;
    return o;
}

TEST(WavefrontPath, CornellBoxMatchesTheMegakernelForEveryLightSampling) {
    const std::unique_ptr<World> s = load("builtin:cornell");
    for (LightSampling strategy : {LightSampling::Mis, LightSampling::Nee, LightSampling::Bsdf}) {
        RenderOptions o = small_path_options(40, 30, 3);
        o.light_sampling = strategy;
        expect_wavefront_matches(*s, s->camera(), o,
                                 "cornell " + to_string(strategy));
    }
}

TEST(WavefrontPath, EnvironmentLitMaterialSpheresMatchTheMegakernel) {
    const std::unique_ptr<World> s = load("builtin:material-spheres");
    RenderOptions o = small_path_options(40, 30, 2);
    o.max_sample_value = 8.0f;  // the clamp is applied where the megakernel applies it
    expect_wavefront_matches(*s, s->camera(), o, "material-spheres");
}

// A floor under a quad light, a point light and a dim sky, seen through a
// blended (BLEND, alpha 0.5) pane and past a cut-out (MASK) checkerboard:
// pass-throughs, cut-out walks on camera, bounce and shadow rays, and the
// derived shadow streams all take part.
TestScene transparent_scene() {
    TestScene t;
    t.add_quad(Vec3f(0.0f), {3, 0, 0}, {0, 3, 0}, t.add_material(diffuse(Vec3f(0.7f, 0.6f, 0.5f))));
    t.add_quad({0.0f, 0.0f, 2.5f}, {0, 0.8f, 0}, {0.8f, 0, 0}, t.add_material(emitter(Vec3f(5.0f))));  // faces -z

    Texture checker;
    checker.name = "checker";
    checker.width = checker.height = 4;
    checker.channels = 4;
    checker.encoding = TextureEncoding::Linear8;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) {
            const uint8_t a = (x + y) % 2 ? 255 : 0;
            checker.texels8.insert(checker.texels8.end(), {200, 120, 60, a});
        }
    t.scene.textures.push_back(checker);
    Material mask = diffuse(Vec3f(1.0f));
    mask.base_color_texture = 0;
    mask.alpha_mode = AlphaMode::Mask;
    t.add_quad({-0.6f, 0.0f, 1.0f}, {0.8f, 0, 0}, {0, 1.5f, 0}, t.add_material(mask));
    t.scene.meshes.back().uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};

    Material pane = diffuse(Vec3f(0.2f, 0.5f, 0.9f));
    pane.alpha = 0.5f;
    pane.alpha_mode = AlphaMode::Blend;
    t.add_quad({0.7f, 0.0f, 0.7f}, {0.9f, 0, 0}, {0, 1.5f, 0}, t.add_material(pane));
    Material glossy;
    glossy.base_color = Vec3f(0.9f, 0.8f, 0.6f);
    glossy.metallic = 1.0f;
    glossy.roughness = 0.3f;
    t.add_sphere({0.2f, -1.2f, 0.4f}, 0.4f, t.add_material(glossy), 24);

    Light point;
    point.position = {-1.0f, 1.0f, 2.0f};
    point.intensity = 3.0f;
    t.scene.lights.push_back(point);
    t.scene.environment.color = Vec3f(0.1f);
    t.finish(Structure::Bvh);
    return t;
}

TEST(WavefrontPath, CutOutAndBlendedSurfacesMatchTheMegakernel) {
    const TestScene t = transparent_scene();
    const Camera camera = looking_at({0.0f, -3.5f, 3.0f}, {0.0f, 0.0f, 0.4f}, 50.0f);
    for (LightSampling strategy : {LightSampling::Mis, LightSampling::Nee, LightSampling::Bsdf}) {
        RenderOptions o = small_path_options(32, 24, 3);
        o.light_sampling = strategy;
        expect_wavefront_matches(*t.world, camera, o, "transparent " + to_string(strategy));
    }
}

// A wavefront pass over more paths than one chunk holds, with the queue
// sizes it reports: every pixel's path extended in round 0, the active
// queue never growing, and the shadow rays counted per round.
TEST(WavefrontPath, ChunksAndQueueStatistics) {
    const std::unique_ptr<World> s = load("builtin:cornell");
    RenderOptions o = small_path_options(260, 256, 1);  // 66560 paths: two chunks
    ASSERT_GT(uint32_t(o.width * o.height), kWavefrontChunkPaths);
    o.max_depth = 2;
    const WavefrontVariant sorted_on_two_threads[] = {{2, true}};
    expect_wavefront_matches(*s, s->camera(), o, "two chunks",
                             sorted_on_two_threads);

    RenderOptions w = small_path_options(64, 48, 1);
    w.wavefront = true;
    w.sort_rays = true;
    w.max_depth = 4;
    const auto renderer = make_renderer(*s, s->camera(), w);
    renderer->render_pass();
    const PassStats& stats = renderer->last_pass();
    ASSERT_GE(stats.waves.size(), 2u);
    EXPECT_EQ(stats.waves[0].paths, 64u * 48u);
    uint64_t shadows = 0, extended = 0;
    for (size_t i = 0; i < stats.waves.size(); ++i) {
        if (i > 0) EXPECT_LE(stats.waves[i].paths, stats.waves[i - 1].paths) << "round " << i;
        EXPECT_LE(stats.waves[i].shadow_rays, stats.waves[i].paths) << "round " << i;
        shadows += stats.waves[i].shadow_rays;
        extended += stats.waves[i].paths;
    }
    EXPECT_GT(shadows, 0u);
    EXPECT_EQ(stats.shadow_rays, shadows);  // an opaque scene: one any-hit query per connection
    EXPECT_EQ(stats.closest_rays, extended);  // and one closest-hit query per extension
    EXPECT_LE(stats.waves.size(), size_t(w.max_depth) + 1);
    EXPECT_GE(stats.sort_ms, 0.0);
}

TEST(WavefrontPath, DerivedStreamsAreIndependentAndLeaveTheParentAlone) {
    RandomStream parent(5, 1, 9);
    parent.next();
    const uint32_t dimension = parent.dimension();
    RandomStream child = parent.derive(kShadowStreamTag);
    EXPECT_EQ(parent.dimension(), dimension);
    EXPECT_EQ(child.dimension(), 0u);
    RandomStream same = parent.derive(kShadowStreamTag);
    RandomStream other_tag = parent.derive(kShadowStreamTag + 1);
    RandomStream copy = parent;
    copy.next();
    RandomStream later = copy.derive(kShadowStreamTag);  // another dimension: another stream
    const float c = child.next();
    EXPECT_EQ(c, same.next());
    EXPECT_NE(c, other_tag.next());
    EXPECT_NE(c, later.next());
    EXPECT_NE(c, parent.next());

    // The derived numbers are uniform: mean 1/2 within 5 standard errors
    // (variance 1/12), over children of many parents.
    const int n = 20000;
    double sum = 0.0;
    for (int i = 0; i < n; ++i) sum += RandomStream(uint32_t(i), 0, 1).derive(kShadowStreamTag).next();
    EXPECT_NEAR(sum / n, 0.5, 5.0 * std::sqrt(1.0 / 12.0 / n));
}

// Rays with nearly the same origin and direction (moved by far less than a
// cell) almost always share their key; unrelated rays almost never do; and
// the bit split puts the origin cell above the direction cell.
TEST(WavefrontPath, SortKeysAreCloseForCloseRays) {
    Box3f bounds;
    bounds.extend(Vec3f(-1.0f, -2.0f, -3.0f));
    bounds.extend(Vec3f(4.0f, 3.0f, 2.0f));
    RandomStream rng(1, 2, 3);
    auto random_ray = [&] {
        Ray r;
        r.org = bounds.lo + (bounds.hi - bounds.lo) * Vec3f(rng.next(), rng.next(), rng.next());
        r.dir = normalize(Vec3f(rng.next() - 0.5f, rng.next() - 0.5f, rng.next() - 0.5f));
        return r;
    };
    const int n = 2000;
    int same_close = 0, same_far = 0;
    for (int i = 0; i < n; ++i) {
        const Ray a = random_ray();
        Ray b = a;
        b.org += Vec3f(1e-4f, -1e-4f, 1e-4f);           // 1/50 000 of a 5-unit box: far below a 1/64 cell
        b.dir = normalize(b.dir + Vec3f(0.0f, 1e-4f, 0.0f));  // far below a 1/128 direction cell
        same_close += ray_sort_key(a, bounds) == ray_sort_key(b, bounds);
        same_far += ray_sort_key(a, bounds) == ray_sort_key(random_ray(), bounds);
        // The same origin: the 18 origin bits agree whatever the direction.
        Ray c = a;
        c.dir = random_ray().dir;
        EXPECT_EQ(ray_sort_key(a, bounds) >> kRayKeyDirectionBits, ray_sort_key(c, bounds) >> kRayKeyDirectionBits);
    }
    // A perturbation of d crosses one of the ~5 cell borders with chance about
    // 5 * d / cell < 1%; a random pair shares a key with chance 2^-32 per pair
    // for uniform keys (far more for these, but still far below 1%).
    EXPECT_GT(same_close, n * 95 / 100);
    EXPECT_LT(same_far, n / 100);

    // Origins outside the box are clamped into its border cells; a zero direction is valid.
    Ray outside;
    outside.org = bounds.hi + Vec3f(10.0f);
    outside.dir = Vec3f(0.0f);
    Ray corner;
    corner.org = bounds.hi;
    corner.dir = Vec3f(0.0f);
    EXPECT_EQ(ray_sort_key(outside, bounds), ray_sort_key(corner, bounds));
    // Opposite directions land in different cells.
    Ray up = corner, down = corner;
    up.dir = Vec3f(0, 0, 1);
    down.dir = Vec3f(0, 0, -1);
    EXPECT_NE(ray_sort_key(up, bounds), ray_sort_key(down, bounds));
}

TEST(WavefrontPath, QueueSortIsAStablePermutation) {
    const size_t n = 5000;
    std::vector<uint32_t> queue(n), keys(n);
    RandomStream rng(4, 5, 6);
    for (size_t i = 0; i < n; ++i) {
        queue[i] = uint32_t(n - 1 - i);  // paths in some order
        // Few distinct keys (many ties) spread over all four bytes.
        keys[i] = uint32_t(rng.next() * 16.0f) * 0x01020408u;
    }
    std::vector<uint32_t> key_of_path(n);
    for (size_t i = 0; i < n; ++i) key_of_path[queue[i]] = keys[i];
    const std::vector<uint32_t> before = queue;
    sort_queue_by_key(queue, keys);
    std::vector<uint32_t> sorted_paths = queue;
    std::sort(sorted_paths.begin(), sorted_paths.end());
    std::vector<uint32_t> all(n);
    std::iota(all.begin(), all.end(), 0u);
    EXPECT_EQ(sorted_paths, all);  // a permutation
    for (size_t i = 0; i < n; ++i) EXPECT_EQ(keys[i], key_of_path[queue[i]]) << i;  // keys moved with their paths
    for (size_t i = 1; i < n; ++i) {
        ASSERT_LE(keys[i - 1], keys[i]) << i;
        // Stable: equal keys keep their order (the queue started descending).
        if (keys[i - 1] == keys[i]) EXPECT_GT(queue[i - 1], queue[i]) << i;
    }
    EXPECT_NE(queue, before);
}

}  // namespace
}  // namespace rf
