// Primary ray generation: centre, field of view, aspect ratio, thin lens focus.
#include <gtest/gtest.h>

#include <cmath>

#include "rayforge/core/error.h"
#include "rayforge/scene/camera.h"

namespace rf {
namespace {

constexpr float kDegrees = 3.14159265358979f / 180.0f;

Camera test_camera() {
    Camera c;
    c.eye = {1.0f, 2.0f, 3.0f};
    c.target = {1.0f, 2.0f, -7.0f};   // looking down -z
    c.up = {0.0f, 1.0f, 0.0f};
    c.vfov_degrees = 60.0f;
    return c;
}

void expect_vec_near(Vec3f a, Vec3f b, float tol) {
    EXPECT_NEAR(a.x, b.x, tol);
    EXPECT_NEAR(a.y, b.y, tol);
    EXPECT_NEAR(a.z, b.z, tol);
}

TEST(Camera, CentreRayLooksAtTheTarget) {
    Camera c = test_camera();
    CameraFrame f = CameraFrame::make(c, 200, 100);
    Ray r = f.generate(100.0f, 50.0f, 200, 100);
    expect_vec_near(r.org, c.eye, 1e-6f);
    expect_vec_near(r.dir, Vec3f(0.0f, 0.0f, -1.0f), 1e-6f);
    EXPECT_NEAR(length(r.dir), 1.0f, 1e-6f);
}

TEST(Camera, EdgesAreAtHalfTheFieldOfViewAndAspectWidensHorizontally) {
    const int w = 200, h = 100;
    CameraFrame f = CameraFrame::make(test_camera(), w, h);
    // Top edge centre: 30 degrees above the view axis, up is +y.
    Ray top = f.generate(w / 2.0f, 0.0f, w, h);
    EXPECT_NEAR(std::acos(-top.dir.z), 30.0f * kDegrees, 1e-5f);
    EXPECT_GT(top.dir.y, 0.0f);
    // Right edge centre: tan(angle) = aspect * tan(30 deg); right is +x looking down -z.
    Ray right = f.generate(float(w), h / 2.0f, w, h);
    EXPECT_NEAR(right.dir.x / -right.dir.z, 2.0f * std::tan(30.0f * kDegrees), 1e-5f);
    EXPECT_NEAR(right.dir.y, 0.0f, 1e-6f);
    // Top-left corner combines both.
    Ray corner = f.generate(0.0f, 0.0f, w, h);
    EXPECT_NEAR(corner.dir.y / -corner.dir.z, std::tan(30.0f * kDegrees), 1e-5f);
    EXPECT_NEAR(corner.dir.x / -corner.dir.z, -2.0f * std::tan(30.0f * kDegrees), 1e-5f);
}

TEST(Camera, ThinLensRaysConvergeAtTheFocusDistance) {
    Camera c = test_camera();
    c.aperture_radius = 0.25f;
    c.focus_distance = 4.0f;
    const int w = 64, h = 48;
    CameraFrame f = CameraFrame::make(c, w, h);
    for (Vec2f pixel : {Vec2f{32.0f, 24.0f}, Vec2f{5.5f, 40.25f}}) {
        Ray reference = f.generate(pixel.x, pixel.y, w, h, 0.0f, 0.0f);  // lens centre
        Vec3f focus = reference.org + reference.dir * ((c.eye.z - 4.0f - reference.org.z) / reference.dir.z);
        float spread = 0.0f;
        for (Vec2f lens : {Vec2f{0.9f, 0.1f}, Vec2f{0.5f, 0.5f}, Vec2f{0.3f, 0.8f}}) {
            Ray r = f.generate(pixel.x, pixel.y, w, h, lens.x, lens.y);
            spread = std::fmax(spread, length(r.org - c.eye));
            // Where the ray crosses the focus plane z = eye.z - 4.
            float t = (c.eye.z - 4.0f - r.org.z) / r.dir.z;
            expect_vec_near(r.org + r.dir * t, focus, 1e-4f);
        }
        EXPECT_GT(spread, 0.1f);  // the lens really moved the origins
    }
}

TEST(Camera, DegenerateCamerasAreErrors) {
    Camera c = test_camera();
    c.target = c.eye;
    EXPECT_THROW((void)CameraFrame::make(c, 10, 10), Error);
    c = test_camera();
    c.up = {0.0f, 0.0f, 1.0f};  // parallel to the view direction
    EXPECT_THROW((void)CameraFrame::make(c, 10, 10), Error);
    c = test_camera();
    c.vfov_degrees = 180.0f;
    EXPECT_THROW((void)CameraFrame::make(c, 10, 10), Error);
}


// The --camera form reads back the same floats and rejects anything but ten finite numbers.
TEST(Camera, CommandLineFormRoundTripsAndRejectsMalformedText) {
    Camera c = test_camera();
    c.eye = {0.1f, -1e-7f, 123456.789f};
    c.vfov_degrees = 33.3f;
    const Camera back = parse_camera(to_string(c));
    EXPECT_EQ(back.eye, c.eye);
    EXPECT_EQ(back.target, c.target);
    EXPECT_EQ(back.up, c.up);
    EXPECT_EQ(back.vfov_degrees, c.vfov_degrees);
    EXPECT_EQ(parse_camera("0, 1, 3.9, 0,1,0, 0,1,0, 40").eye, Vec3f(0, 1, 3.9f));
    for (const char* bad : {"", "1,2,3", "1,2,3,4,5,6,7,8,9,10,11", "1,2,3,4,5,6,7,8,9,x", "1,2,3,4,5,6,7,8,9,nan",
                            "1,2,3,4,5,6,7,8,9,1e39", "1,2,3,4,5,6,7,8,9,10,", ",1,2,3,4,5,6,7,8,9"})
        EXPECT_THROW((void)parse_camera(bad), Error) << bad;
}

}  // namespace
}  // namespace rf
