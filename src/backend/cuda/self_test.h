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

}  // namespace rf::cuda::self_test
