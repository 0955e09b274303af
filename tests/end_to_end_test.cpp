// Renders builtin:cornell and compares it with committed reference images.
//
// To regenerate the references after an intended change of the output, run
//   RAYFORGE_UPDATE_REFERENCES=1 ./rayforge_tests --gtest_filter='EndToEnd*'
// look at tests/data/reference/*.png, and commit them.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"
#include "math/color.h"
#include "test_paths.h"

namespace rf {
namespace {

struct Comparison {
    double mean_abs = 0.0;       // over all channels, in 8-bit sRGB code values
    double share_far = 0.0;      // pixels with any channel off by more than the threshold
};

Comparison compare_srgb(const Image& a, const Image& b, float far_threshold) {
    Comparison c;
    size_t far = 0;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        Vec3f sa = linear_to_srgb(a.pixels[i]) * 255.0f, sb = linear_to_srgb(b.pixels[i]) * 255.0f;
        Vec3f d = abs(sa - sb);
        c.mean_abs += double(d.x + d.y + d.z) / 3.0;
        far += max_component(d) > far_threshold;
    }
    c.mean_abs /= double(a.pixels.size());
    c.share_far = double(far) / double(a.pixels.size());
    return c;
}

// Box-filters an image by `factor` in each direction: Monte Carlo noise, which
// differs wherever a float rounding sends one path another way, averages
// out; what the image shows does not.
Image downsample(const Image& image, int factor) {
    Image small(image.width / factor, image.height / factor);
    for (int y = 0; y < small.height; ++y)
        for (int x = 0; x < small.width; ++x) {
            Vec3f sum(0.0f);
            for (int dy = 0; dy < factor; ++dy)
                for (int dx = 0; dx < factor; ++dx) sum += image.at(x * factor + dx, y * factor + dy);
            small.at(x, y) = sum / float(factor * factor);
        }
    return small;
}

void check_against_reference(IntegratorKind integrator, int spp, const std::string& reference_name,
                             int downsample_factor = 1) {
    const std::unique_ptr<World> world = open_world("builtin:cornell");
    RenderOptions options;
    options.width = 160;
    options.height = 120;
    options.spp = spp;
    options.integrator = integrator;
    options.seed = 1;
    // Clamped samples keep a rare caustic path (the spheres focus the light)
    // from deciding a whole block; the comparison is about everything else.
    if (integrator == IntegratorKind::Path) options.max_sample_value = 4.0f;
    Image image = render(*world, world->camera(), options);

    std::string reference_path = test::data_path("reference/" + reference_name);
    const char* update = std::getenv("RAYFORGE_UPDATE_REFERENCES");
    if (update && std::string(update) == "1") {
        write_image(reference_path, image);
        GTEST_SKIP() << "wrote " << reference_path;
    }
    // Compare what the PNG holds: quantise this render the same way.
    std::string written = test::temp_dir("end_to_end_" + reference_name) + "/" + reference_name;
    write_image(written, image);
    Image actual = read_image(written);
    Image reference = read_image(reference_path);
    ASSERT_EQ(reference.width, actual.width);
    ASSERT_EQ(reference.height, actual.height);
    if (downsample_factor > 1) {
        actual = downsample(actual, downsample_factor);
        reference = downsample(reference, downsample_factor);
    }
    Comparison c = compare_srgb(actual, reference, 24.0f);
    EXPECT_LT(c.mean_abs, 1.5) << "mean |difference| in sRGB code values; see " << written;
    EXPECT_LT(c.share_far, 0.01) << "share of pixels off by more than 24 code values; see " << written;
}

TEST(EndToEnd, CornellWhittedMatchesReference) {
    check_against_reference(IntegratorKind::Whitted, 4, "cornell_whitted.png");
}

// The path tracer's noise is compared at a quarter of the resolution.
TEST(EndToEnd, CornellPathMatchesReference) {
    check_against_reference(IntegratorKind::Path, 32, "cornell_path.png", 4);
}

TEST(EndToEnd, CornellAoMatchesReference) {
    check_against_reference(IntegratorKind::AmbientOcclusion, 4, "cornell_ao.png", 2);
}

TEST(EndToEnd, CornellNormalsMatchesReference) {
    check_against_reference(IntegratorKind::Normals, 1, "cornell_normals.png");
}

}  // namespace
}  // namespace rf
