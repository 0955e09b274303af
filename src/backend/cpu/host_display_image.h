// The CPU renderer's display image: RGBA8 pixels in host memory, tone-mapped
// from the mean film in parallel rows by render/tone_map.h (PNG output's
// per-pixel code, so the display and a written PNG hold the same bytes).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/render/display.h"
#include "rayforge/render/image.h"
#include "rayforge/render/tone_mapping.h"

namespace rf::cpu {

class HostDisplayImage final : public DisplayImage {
public:
    [[nodiscard]] Device device() const override { return {}; }
    [[nodiscard]] int width() const override { return width_; }
    [[nodiscard]] int height() const override { return height_; }
    [[nodiscard]] const uint8_t* host_pixels() const override { return pixels_.data(); }
    [[nodiscard]] const void* device_pixels() const override { return nullptr; }
    [[nodiscard]] std::vector<uint8_t> download() const override { return pixels_; }

    // Tone-maps the mean sums[i] * scale (a width x height film of per-pixel
    // sums over passes, scale = 1 / passes, as Renderer::image() computes it)
    // into this image, resized to the film.
    void assign(std::span<const Vec3f> sums, float scale, int width, int height, const ToneMapping& tone);

private:
    int width_ = 0, height_ = 0;
    std::vector<uint8_t> pixels_;
};

}  // namespace rf::cpu
