#include "backend/cuda/display_image.h"

#include <cuda_gl_interop.h>
#include <cuda_runtime.h>

#include <string>

#include "backend/backends.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"
#include "render/tone_map.h"

namespace rf::cuda {
namespace {

__global__ void tone_map_kernel(const Vec3f* sums, float scale, ToneMapping tone, uint32_t* pixels, uint32_t count) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= count) return;
    uint8_t rgb[3];
    tone_map_pixel(sums[i] * scale, tone, rgb);
    pixels[i] = uint32_t(rgb[0]) | (uint32_t(rgb[1]) << 8) | (uint32_t(rgb[2]) << 16) | 0xff000000u;
}

// A GL buffer registered with CUDA; unregistered when destroyed.
class CudaGlPixelBuffer final : public GlPixelBuffer {
public:
    CudaGlPixelBuffer(int device_index, unsigned int gl_buffer) : device_index_(device_index) {
        RF_CUDA_CHECK(cudaSetDevice(device_index_));
        const cudaError_t status =
            cudaGraphicsGLRegisterBuffer(&resource_, gl_buffer, cudaGraphicsRegisterFlagsWriteDiscard);
        if (status != cudaSuccess) {
            (void)cudaGetLastError();
            throw Error("cuda:" + std::to_string(device_index_) + ": cannot register OpenGL buffer " +
                        std::to_string(gl_buffer) + " with CUDA (" + cudaGetErrorString(status) +
                        "); the OpenGL context must run on this NVIDIA GPU");
        }
        // Its own non-blocking stream: the copy must not wait for the
        // renderer's next pass queued on the default stream by another thread.
        const cudaError_t made = cudaStreamCreateWithFlags(&stream_, cudaStreamNonBlocking);
        if (made != cudaSuccess) {
            cudaGraphicsUnregisterResource(resource_);
            RF_CUDA_CHECK(made);
        }
    }
    ~CudaGlPixelBuffer() override {
        cudaGraphicsUnregisterResource(resource_);
        cudaStreamDestroy(stream_);
    }
    CudaGlPixelBuffer(const CudaGlPixelBuffer&) = delete;
    CudaGlPixelBuffer& operator=(const CudaGlPixelBuffer&) = delete;

    [[nodiscard]] Device device() const override { return {Device::Kind::Cuda, device_index_}; }

    void copy_from(const DisplayImage& image) override {
        if (!(image.device() == device()) || image.device_pixels() == nullptr)
            throw Error("GL pixel buffer on " + to_string(device()) + ": the display image is on " +
                        to_string(image.device()));
        RF_CUDA_CHECK(cudaSetDevice(device_index_));
        const size_t bytes = size_t(image.width()) * size_t(image.height()) * 4;
        RF_CUDA_CHECK(cudaGraphicsMapResources(1, &resource_, stream_));
        void* mapped = nullptr;
        size_t mapped_bytes = 0;
        const cudaError_t pointer = cudaGraphicsResourceGetMappedPointer(&mapped, &mapped_bytes, resource_);
        const bool fits = pointer == cudaSuccess && mapped_bytes >= bytes;
        const cudaError_t copy =
            fits ? cudaMemcpyAsync(mapped, image.device_pixels(), bytes, cudaMemcpyDeviceToDevice, stream_)
                 : cudaSuccess;
        RF_CUDA_CHECK(cudaGraphicsUnmapResources(1, &resource_, stream_));  // after the copy, in stream order
        RF_CUDA_CHECK(cudaStreamSynchronize(stream_));
        RF_CUDA_CHECK(pointer);
        if (!fits)
            throw Error("GL pixel buffer: " + std::to_string(mapped_bytes) + " bytes cannot hold a " +
                        std::to_string(image.width()) + "x" + std::to_string(image.height()) + " image");
        RF_CUDA_CHECK(copy);
    }

private:
    int device_index_;
    cudaGraphicsResource_t resource_ = nullptr;
    cudaStream_t stream_ = nullptr;
};

}  // namespace

std::vector<uint8_t> DeviceDisplayImage::download() const {
    std::vector<uint32_t> words(size_t(width_) * size_t(height_));
    RF_CUDA_CHECK(cudaSetDevice(device_index_));
    pixels_.download(words);
    std::vector<uint8_t> bytes(words.size() * 4);
    for (size_t i = 0; i < words.size(); ++i)
        for (int k = 0; k < 4; ++k) bytes[4 * i + size_t(k)] = uint8_t(words[i] >> (8 * k));
    return bytes;
}

void DeviceDisplayImage::assign(const Vec3f* sums, float scale, int width, int height, const ToneMapping& tone) {
    RF_CUDA_CHECK(cudaSetDevice(device_index_));
    const uint32_t count = uint32_t(width) * uint32_t(height);
    if (pixels_.size() != count) pixels_.allocate(count);
    width_ = width;
    height_ = height;
    if (count == 0) return;
    launch(tone_map_kernel, count, sums, scale, tone, pixels_.data(), count);
    RF_CUDA_CHECK(cudaDeviceSynchronize());
}

std::unique_ptr<GlPixelBuffer> register_gl_pixel_buffer(int index, unsigned int gl_buffer) {
    require_device(index);
    return std::make_unique<CudaGlPixelBuffer>(index, gl_buffer);
}

}  // namespace rf::cuda
