// Failure injection for the GPU tests (tests/gpu): the error paths of the
// CUDA backend must produce clean rf::Errors, and these calls make them
// happen on purpose. No CUDA header needed to include this.
#pragma once

#include <cstddef>

namespace rf::cuda::self_test {

// Allocates (and frees) a device buffer of `bytes`: an absurd size must
// throw "out of device memory: buffer 'self-test buffer' asked for N bytes".
void allocate_device_buffer(size_t bytes);

// Launches an empty kernel with an invalid block size (2048 threads): must
// throw "CUDA error at <file>:<line>: ... invalid configuration argument".
void launch_invalid_kernel();

}  // namespace rf::cuda::self_test
