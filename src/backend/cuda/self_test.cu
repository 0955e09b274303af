// Failure injection for the GPU tests (self_test.h).
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/self_test.h"

namespace rf::cuda::self_test {

namespace {
__global__ void empty_kernel() {}

__global__ void add_kernel(uint32_t* values, uint32_t count, uint32_t delta) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < count) values[i] += delta;
}
}  // namespace

void allocate_device_buffer(size_t bytes) { DeviceBuffer<unsigned char> buffer("self-test buffer", bytes); }

void launch_invalid_kernel() {
    empty_kernel<<<1, 2048>>>();  // more threads per block than any CUDA device allows
    RF_CUDA_CHECK(cudaGetLastError());
}

std::vector<uint32_t> add_on_device(const std::vector<uint32_t>& values, uint32_t delta) {
    const auto count = uint32_t(values.size());
    DeviceBuffer<uint32_t> buffer("self-test values", count);
    buffer.upload(std::span<const uint32_t>(values));
    launch(add_kernel, count, buffer.data(), count, delta);
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    std::vector<uint32_t> result(count);
    buffer.download(std::span<uint32_t>(result));
    return result;
}

DeviceBytes::DeviceBytes(size_t bytes, int device) {
    RF_CUDA_CHECK(cudaSetDevice(device));
    RF_CUDA_CHECK(cudaMalloc(&data_, bytes));
    cudaStream_t stream = nullptr;
    RF_CUDA_CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
    stream_ = stream;
}

DeviceBytes::~DeviceBytes() {
    if (stream_) cudaStreamDestroy(static_cast<cudaStream_t>(stream_));
    if (data_) cudaFree(data_);
}

void DeviceBytes::upload(const void* host, size_t bytes) {
    RF_CUDA_CHECK(cudaMemcpy(data_, host, bytes, cudaMemcpyHostToDevice));
}

void DeviceBytes::download(void* host, size_t bytes) const {
    RF_CUDA_CHECK(cudaMemcpy(host, data_, bytes, cudaMemcpyDeviceToHost));
}

}  // namespace rf::cuda::self_test
