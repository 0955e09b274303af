// Every CUDA call goes through RF_CUDA_CHECK so a failure becomes an rf::Error
// naming the file, the line and CUDA's own error string.
#pragma once

#include <string>

#include <cuda_runtime.h>

#include "rayforge/core/error.h"

namespace rf::cuda {

[[noreturn]] inline void throw_cuda_error(cudaError_t status, const char* call, const char* file, int line) {
    throw Error(std::string("CUDA error at ") + file + ":" + std::to_string(line) + ": " + call + ": " +
                cudaGetErrorString(status));
}

}  // namespace rf::cuda

#define RF_CUDA_CHECK(call)                                                        \
    do {                                                                           \
        cudaError_t rf_status_ = (call);                                           \
        if (rf_status_ != cudaSuccess)                                             \
            ::rf::cuda::throw_cuda_error(rf_status_, #call, __FILE__, __LINE__);   \
    } while (0)
