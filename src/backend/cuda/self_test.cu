// Failure injection for the GPU tests (self_test.h).
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/self_test.h"

namespace rf::cuda::self_test {

namespace {
__global__ void empty_kernel() {}
}  // namespace

void allocate_device_buffer(size_t bytes) { DeviceBuffer<unsigned char> buffer("self-test buffer", bytes); }

void launch_invalid_kernel() {
    empty_kernel<<<1, 2048>>>();  // more threads per block than any CUDA device allows
    RF_CUDA_CHECK(cudaGetLastError());
}

}  // namespace rf::cuda::self_test
