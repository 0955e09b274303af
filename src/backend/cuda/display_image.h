// The CUDA renderer's display image: RGBA8 pixels in device memory, written
// by a kernel over the films with PNG output's per-pixel tone mapping
// (render/tone_map.h), and the OpenGL pixel buffers they are copied into
// (CUDA-OpenGL interop), so a viewer shows a device render without a trip
// through host memory.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "backend/cuda/device_buffer.h"
#include "rayforge/math/vec.h"
#include "rayforge/render/display.h"
#include "rayforge/render/tone_mapping.h"

namespace rf::cuda {

class DeviceDisplayImage final : public DisplayImage {
public:
    explicit DeviceDisplayImage(int device_index) : device_index_(device_index) {}
    [[nodiscard]] Device device() const override { return {Device::Kind::Cuda, device_index_}; }
    [[nodiscard]] int width() const override { return width_; }
    [[nodiscard]] int height() const override { return height_; }
    [[nodiscard]] const uint8_t* host_pixels() const override { return nullptr; }
    [[nodiscard]] const void* device_pixels() const override { return pixels_.data(); }
    [[nodiscard]] std::vector<uint8_t> download() const override;

    // pixels = tone_map(sums[i] * scale), with sums a width x height film in
    // device memory; waits for the kernel, so the image is complete on return.
    void assign(const Vec3f* sums, float scale, int width, int height, const ToneMapping& tone);

private:
    int device_index_ = 0;
    int width_ = 0, height_ = 0;
    DeviceBuffer<uint32_t> pixels_{"display image"};
};

}  // namespace rf::cuda
