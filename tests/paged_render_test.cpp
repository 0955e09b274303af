// Rendering paged scenes (docs/paged-scenes.md), opened as worlds: images equal the in-core renderer's
// within quantisation, are the same bytes whatever the cache budget, the
// resident set stays within the budget plus the fixed overhead, and the
// CLI's convert / generate / info / render work on paged files.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "cli_runner.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "render_test_scene.h"
#include "test_paths.h"

namespace rf {
namespace {

// Spheres and boxes on a floor under a sun and a sky colour: no emitting
// triangles (paged scenes do not sample them as lights) and no cut-outs.
struct PagedRenderFixture {
    TestScene t;
    std::string path;
    Camera camera;
    PagedRenderFixture() {
        const uint32_t floor = t.add_material(diffuse({0.6f, 0.6f, 0.55f}));
        const uint32_t red = t.add_material(diffuse({0.7f, 0.2f, 0.15f}));
        Material metal;
        metal.base_color = {0.9f, 0.8f, 0.5f};
        metal.metallic = 1.0f;
        metal.roughness = 0.2f;
        const uint32_t gold = t.add_material(metal);
        t.add_quad({0, 0, 0}, {4, 0, 0}, {0, 0, -4}, floor);
        t.add_sphere({-1.0f, 0.8f, 0.0f}, 0.8f, red, 64);
        t.add_sphere({1.0f, 0.6f, 0.5f}, 0.6f, gold, 64);
        t.add_box({0.2f, 0.3f, -1.4f}, 0.3f, red);
        Light sun;
        sun.type = LightType::Directional;
        sun.direction = normalize(Vec3f(-0.3f, -1.0f, -0.4f));
        sun.intensity = 2.5f;
        t.scene.lights.push_back(sun);
        t.scene.environment.color = {0.3f, 0.4f, 0.6f};
        camera = looking_at({0.5f, 2.0f, 5.0f}, {0.0f, 0.5f, 0.0f}, 40.0f);
        t.scene.camera = camera;
        t.finish(Structure::Bvh);
        path = test::temp_dir("paged_render") + "/scene.rfpack";
        PagedWriteOptions w;
        w.quads_per_page = 256;
        convert_to_paged(t.scene, path, w);
    }
};

const PagedRenderFixture& fixture() {
    static const PagedRenderFixture f;
    return f;
}

Image paged_render(const RenderOptions& options, size_t budget) {
    WorldOptions o;
    o.paged.memory_budget = budget;
    auto world = open_world(fixture().path, o);
    auto renderer = make_renderer(*world, fixture().camera, options);
    render_progressive(*renderer);
    return renderer->image();
}

struct ImageDifference {
    double mean = 0.0;        // mean |a - b| over channels, relative to the mean of b
    double outliers = 0.0;    // fraction of pixels with a channel off by more than 0.1 + 10%
};

ImageDifference compare(const Image& a, const Image& b) {
    ImageDifference d;
    double sum = 0.0, reference = 0.0;
    size_t outliers = 0;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        bool off = false;
        for (int c = 0; c < 3; ++c) {
            const double x = a.pixels[i][c], y = b.pixels[i][c];
            sum += std::fabs(x - y);
            reference += std::fabs(y);
            off |= std::fabs(x - y) > 0.1 + 0.1 * std::fabs(y);
        }
        outliers += off ? 1 : 0;
    }
    d.mean = reference > 0.0 ? sum / reference : 0.0;
    d.outliers = double(outliers) / double(a.pixels.size());
    return d;
}

TEST(PagedRender, ImagesMatchTheInCoreRendererWithinQuantisation) {
    const PagedRenderFixture& f = fixture();
    for (IntegratorKind kind : {IntegratorKind::Whitted, IntegratorKind::AmbientOcclusion, IntegratorKind::Normals,
                                IntegratorKind::Path}) {
        RenderOptions o = options_for(kind, 96, 72);
        o.spp = kind == IntegratorKind::Path ? 4 : 1;
        o.wavefront = true;
        const Image in_core = f.t.render_with(f.camera, o);
        const Image paged = paged_render(o, size_t(64) << 20);
        const ImageDifference d = compare(paged, in_core);
        double brightness = 0.0;
        for (const Vec3f& p : in_core.pixels) brightness += double(p.x + p.y + p.z);
        ASSERT_GT(brightness / double(in_core.pixels.size()), 0.05) << integrator_name(kind) << ": a dark reference proves nothing";
        std::printf("%s: mean difference %.5f, outliers %.4f\n", integrator_name(kind).c_str(), d.mean, d.outliers);
        // The same per-sample code over geometry moved by at most half a
        // 16-bit step: a few silhouette pixels change, the rest agree.
        EXPECT_LT(d.mean, 0.01) << integrator_name(kind);
        EXPECT_LT(d.outliers, 0.01) << integrator_name(kind);
    }
}

TEST(PagedRender, ImagesAreTheSameBytesWhateverTheBudget) {
    for (IntegratorKind kind : {IntegratorKind::Whitted, IntegratorKind::Path}) {
        RenderOptions o = options_for(kind, 64, 48);
        o.spp = 2;
        const Image roomy = paged_render(o, size_t(64) << 20);
        // 160 KB: a few geometry pages and attribute pages at a time.
        const Image tiny = paged_render(o, size_t(160) << 10);
        ASSERT_EQ(roomy.pixels.size(), tiny.pixels.size());
        for (size_t i = 0; i < roomy.pixels.size(); ++i)
            for (int c = 0; c < 3; ++c) ASSERT_EQ(roomy.pixels[i][c], tiny.pixels[i][c]) << integrator_name(kind) << " pixel " << i;
    }
}

size_t resident_set_bytes() {
    std::ifstream status("/proc/self/status");
    std::string key;
    while (status >> key) {
        if (key == "VmRSS:") {
            size_t kb = 0;
            status >> kb;
            return kb * 1024;
        }
        std::getline(status, key);
    }
    return 0;
}

// A scene file several times the budget, rendered: the process grows by at
// most the budget plus the stated fixed overhead (resident levels, films,
// the wavefront's queues), never by the file.
TEST(PagedRender, ResidentSetStaysWithinTheBudgetPlusTheFixedOverhead) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
    GTEST_SKIP() << "a sanitizer's shadow memory and quarantine make the resident set meaningless here";
#endif
    const std::string path = test::temp_dir("paged_rss") + "/spheres.rfpack";
    Scene spheres = make_builtin_scene("spheres");
    spheres.finalize();
    PagedWriteOptions flat;
    flat.flatten_instances = true;  // a file several times the budget
    flat.codec = PagedCodec::None;  // (so that what is cached is what the file holds)
    const PagedWriteReport written = convert_to_paged(spheres, path, flat);
    const size_t budget = size_t(1) << 20;
    ASSERT_GT(written.file_bytes, 6 * budget);
    const size_t before = resident_set_bytes();
    WorldOptions o;
    o.paged.memory_budget = budget;
    auto world = open_world(path, o);
    const PagedScene* scene = &world->paged_scene();
    RenderOptions r = options_for(IntegratorKind::Path, 160, 120);
    r.spp = 3;
    auto renderer = make_renderer(*world, world->camera(), r);
    render_progressive(*renderer);
    const size_t grown = resident_set_bytes() - std::min(before, resident_set_bytes());
    // Fixed overhead: resident levels + films (4 x 12 bytes a pixel) + wavefront queues (~250 bytes a path).
    const size_t fixed = scene->info().resident_bytes + size_t(160 * 120) * (48 + 256) + (size_t(4) << 20);
    EXPECT_LE(scene->memory_bytes(), budget + scene->info().resident_bytes);
    EXPECT_LE(grown, budget + fixed) << "grew " << grown << " bytes for a " << written.file_bytes << "-byte file";
    uint64_t read = 0;
    for (const PageCacheReport& c : scene->caches()) read += c.bytes_read;
    EXPECT_GT(read, budget);  // the pages went through the cache, more than it holds
}

TEST(PagedRender, CliConvertsGeneratesDescribesAndRendersPagedFiles) {
    const std::string dir = test::temp_dir("paged_cli");
    const test::CliResult convert = test::run_cli("convert builtin:cornell -o " + dir + "/c.rfpack --zstd -q");
    ASSERT_EQ(convert.exit_code, 0) << convert.err;
    EXPECT_NE(convert.out.find("quads"), std::string::npos);
    EXPECT_NE(convert.out.find(" bytes a unique triangle"), std::string::npos) << convert.out;
    const test::CliResult info = test::run_cli("info " + dir + "/c.rfpack");
    ASSERT_EQ(info.exit_code, 0) << info.err;
    EXPECT_NE(info.out.find("paged scene"), std::string::npos);
    // The density, file bytes / triangles, as convert printed it.
    const auto density = [](const std::string& text) {
        const size_t end = text.find(" bytes a unique triangle");
        const size_t start = text.find_last_of(" (", end - 1);
        return end == std::string::npos ? -1.0 : std::stod(text.substr(start + 1, end - start - 1));
    };
    EXPECT_GT(density(info.out), 0.0) << info.out;
    EXPECT_EQ(density(info.out), density(convert.out));
    const test::CliResult render =
        test::run_cli("render " + dir + "/c.rfpack -o " + dir + "/c.png --res 32x24 --memory-budget 1M -q");
    ASSERT_EQ(render.exit_code, 0) << render.err;
    EXPECT_NE(render.out.find("caches:"), std::string::npos);
    const test::CliResult generate =
        test::run_cli("generate terrain --triangles 20K -o " + dir + "/t.rfpack --compact-attributes -q");
    ASSERT_EQ(generate.exit_code, 0) << generate.err;
    EXPECT_NE(generate.out.find(" bytes a unique triangle"), std::string::npos) << generate.out;
    const test::CliResult obj = test::run_cli("generate terrain-statues --triangles 5K -o " + dir + "/s.obj -q");
    ASSERT_EQ(obj.exit_code, 0) << obj.err;
    EXPECT_EQ(test::run_cli("info " + dir + "/s.obj").exit_code, 0);
    // Errors: one line, exit 1 (runtime) or 2 (usage).
    std::ofstream(dir + "/bad.rfpack") << "RFPACK\r\nnot really";
    const test::CliResult bad = test::run_cli("render " + dir + "/bad.rfpack -o " + dir + "/x.png");
    EXPECT_EQ(bad.exit_code, 1);
    EXPECT_NE(bad.err.find("rayforge: error:"), std::string::npos);
    EXPECT_EQ(test::lines_of(bad.err).size(), 1u) << bad.err;
    EXPECT_EQ(test::run_cli("render " + dir + "/c.rfpack -o " + dir + "/x.png --memory-budget lots").exit_code, 1);
    EXPECT_EQ(test::run_cli("generate nothing -o " + dir + "/x.rfpack").exit_code, 2);
    const test::CliResult again = test::run_cli("convert " + dir + "/c.rfpack -o " + dir + "/d.rfpack");
    EXPECT_EQ(again.exit_code, 1);
    EXPECT_NE(again.err.find("already a paged scene"), std::string::npos) << again.err;
}

}  // namespace
}  // namespace rf
