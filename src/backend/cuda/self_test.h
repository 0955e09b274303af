// Failure injection for the GPU tests (tests/gpu): the error paths of the
// CUDA backend must produce clean rf::Errors, and these calls make them
// happen on purpose. No CUDA header needed to include this.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace rf::cuda::self_test {

// Allocates (and frees) a device buffer of `bytes`: an absurd size must
// throw "out of device memory: buffer 'self-test buffer' asked for N bytes".
void allocate_device_buffer(size_t bytes);

// Launches an empty kernel with an invalid block size (2048 threads): must
// throw "CUDA error at <file>:<line>: ... invalid configuration argument".
void launch_invalid_kernel();

// The smallest real use of the device: uploads `values`, adds `delta` to each
// in a kernel and downloads them. scripts/gpu-run.sh runs it under
// compute-sanitizer first, to tell a runtime that refuses the sanitizer from
// a memory error of ours.
std::vector<uint32_t> add_on_device(const std::vector<uint32_t>& values, uint32_t delta);

// Memory of a device, as a program's own cudaMalloc (or a DLPack array)
// hands it to the device batches (Accel::intersect_on_device), and a
// stream of its own; freed by the destructor.
class DeviceBytes {
public:
    DeviceBytes(size_t bytes, int device);
    ~DeviceBytes();
    DeviceBytes(const DeviceBytes&) = delete;
    DeviceBytes& operator=(const DeviceBytes&) = delete;
    [[nodiscard]] void* data() const { return data_; }
    [[nodiscard]] void* stream() const { return stream_; }  // a cudaStream_t
    void upload(const void* host, size_t bytes);
    void download(void* host, size_t bytes) const;

private:
    void* data_ = nullptr;
    void* stream_ = nullptr;
};

}  // namespace rf::cuda::self_test
