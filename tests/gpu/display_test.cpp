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
#include "rayforge/world.h"

namespace rf {
namespace {

TEST(GpuDisplay, DeviceImageHoldsThePngCodesOfTheMean) {
    RF_REQUIRE_DEVICE();
    const auto world = open_world("builtin:cornell", gpu_test::world_on_device(GpuKernel::Cwbvh));
    RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.spp = 3;
    o.integrator = IntegratorKind::Path;
    const auto renderer = make_renderer(*world, world->camera(), o);
    const auto display = renderer->make_display_image();
    EXPECT_EQ(display->device(), world->device());
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
    const auto cpu_world = open_world("builtin:cornell");
    const auto cpu = make_renderer(*cpu_world, cpu_world->camera(), o);
    EXPECT_THROW(renderer->update_display(*cpu->make_display_image(), {}), Error);
}

TEST(GpuDisplay, RegisteringAGlBufferWithoutAContextIsAnError) {
    RF_REQUIRE_DEVICE();
    EXPECT_THROW((void)register_gl_pixel_buffer(Device{Device::Kind::Cuda, 0}, 1u), Error);
    EXPECT_THROW((void)register_gl_pixel_buffer(Device{}, 1u), Error);
}

}  // namespace
}  // namespace rf
