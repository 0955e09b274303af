// rf::register_gl_pixel_buffer: CUDA-OpenGL interop lives in the CUDA backend.
#include "backend/backends.h"
#include "rayforge/core/error.h"
#include "rayforge/render/display.h"

namespace rf {

std::unique_ptr<GlPixelBuffer> register_gl_pixel_buffer(const Device& device, unsigned int gl_buffer) {
    if (!device.is_cuda())
        throw Error("a GL pixel buffer is registered with a CUDA device, not with " + to_string(device) +
                    " (a CPU renderer's display image is in host memory)");
    return cuda::register_gl_pixel_buffer(device.index, gl_buffer);
}

}  // namespace rf
