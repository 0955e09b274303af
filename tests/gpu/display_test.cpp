// The CUDA renderer's display image (what `rayforge view --device cuda`
// shows): written on the device by the tone-map kernel over the films, it
// must hold the PNG codes of the renderer's own mean image (the device's
// sRGB encoding may differ by one code from the host's table), and live in
// device memory, for the OpenGL pixel buffer copy. Registering a GL buffer
// without a GL context, or on the CPU, is a clean error.
#include <gtest/gtest.h>

#include <cstdlib>

#include "gpu_test_device.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/render/render.h"

namespace rf {
namespace {

TEST(GpuDisplay, DeviceImageHoldsThePngCodesOfTheMean) {
    RF_REQUIRE_DEVICE();
    const Scene scene = make_builtin_scene("cornell");
    const SceneGeometry g = SceneGeometry::build(scene);
    const auto accel = build_accel(g, gpu_test::on_device(GpuKernel::Cwbvh));
    RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.spp = 3;
    o.integrator = IntegratorKind::Path;
    o.device = accel->device();
    const auto renderer = make_renderer(scene, g, *accel, scene.camera_or_default(), o);
    const auto display = renderer->make_display_image();
    EXPECT_EQ(display->device(), o.device);
    render_progressive(*renderer);
    const Image mean = renderer->image();
    for (ToneCurve curve : {ToneCurve::Clamp, ToneCurve::Aces}) {
        const ToneMapping tone{1.5f, curve};
        renderer->update_display(*display, tone);
        ASSERT_EQ(display->width(), 64);
        EXPECT_EQ(display->host_pixels(), nullptr);
        EXPECT_NE(display->device_pixels(), nullptr);
        const std::vector<uint8_t> pixels = display->download();
        ASSERT_EQ(pixels.size(), mean.pixels.size() * 4);
        size_t off_by_one = 0;
        for (size_t i = 0; i < mean.pixels.size(); ++i) {
            uint8_t expected[3];
            tone_map_srgb8(mean.pixels[i], tone, expected);
            for (int k = 0; k < 3; ++k) {
                const int d = std::abs(int(pixels[4 * i + size_t(k)]) - int(expected[k]));
                ASSERT_LE(d, 1) << "pixel " << i;
                off_by_one += d;
            }
            ASSERT_EQ(pixels[4 * i + 3], 255);
        }
        EXPECT_LE(off_by_one, mean.pixels.size() * 3 / 100) << "the encodings should rarely disagree";
    }
    // A CPU display image is not one of this renderer's.
    const auto cpu_accel = build_accel(g);
    RenderOptions on_cpu = o;
    on_cpu.device = {};
    const auto cpu = make_renderer(scene, g, *cpu_accel, scene.camera_or_default(), on_cpu);
    EXPECT_THROW(renderer->update_display(*cpu->make_display_image(), {}), Error);
}

TEST(GpuDisplay, RegisteringAGlBufferWithoutAContextIsAnError) {
    RF_REQUIRE_DEVICE();
    EXPECT_THROW((void)register_gl_pixel_buffer(Device{Device::Kind::Cuda, 0}, 1u), Error);
    EXPECT_THROW((void)register_gl_pixel_buffer(Device{}, 1u), Error);
}

}  // namespace
}  // namespace rf
