// Showing a renderer's image on screen: an 8-bit sRGB RGBA copy of its mean
// image, tone-mapped exactly as PNG output is, kept where the renderer lives
// (host memory for a CPU renderer, device memory for a CUDA one), and, for a
// CUDA renderer, an OpenGL pixel buffer object registered with CUDA
// (CUDA-OpenGL interop) so the image reaches a texture without a trip
// through host memory.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "rayforge/backend/device.h"

namespace rf {

// Made by Renderer::make_display_image and filled by Renderer::update_display;
// rows top to bottom, 4 bytes per pixel (R, G, B, 255).
class DisplayImage {
public:
    virtual ~DisplayImage() = default;
    [[nodiscard]] virtual Device device() const = 0;
    [[nodiscard]] virtual int width() const = 0;
    [[nodiscard]] virtual int height() const = 0;
    // The pixels in host memory; nullptr for an image in device memory.
    [[nodiscard]] virtual const uint8_t* host_pixels() const = 0;
    // The pixels in device memory (a CUDA device pointer); nullptr on the host.
    [[nodiscard]] virtual const void* device_pixels() const = 0;
    // A host copy of the pixels, downloaded from the device when they live there.
    [[nodiscard]] virtual std::vector<uint8_t> download() const = 0;
};

// An OpenGL buffer object of the caller's context registered with CUDA on a
// device. Register, copy and destroy it on the thread whose OpenGL context
// made the buffer, with that context current.
class GlPixelBuffer {
public:
    virtual ~GlPixelBuffer() = default;
    // Copies `image` (a display image on this buffer's device, at most as
    // many bytes as the buffer holds) into the buffer, device to device; the
    // buffer then feeds glTexSubImage2D as a GL_PIXEL_UNPACK_BUFFER.
    virtual void copy_from(const DisplayImage& image) = 0;
    [[nodiscard]] virtual Device device() const = 0;
};

// Registers OpenGL buffer `gl_buffer` (a name from glGenBuffers, storage
// already allocated) with CUDA device `device`. Throws rf::Error on the CPU
// device, in a build without the CUDA backend, or when CUDA refuses (no
// interop-capable context, e.g. a software OpenGL).
std::unique_ptr<GlPixelBuffer> register_gl_pixel_buffer(const Device& device, unsigned int gl_buffer);

}  // namespace rf
