// Kernel launches of the CUDA backend: the block count for N threads (one
// thread per item, or a capped grid whose threads stride over the items),
// and launch(), which launches and checks the launch, so a bad
// configuration fails where it is made, naming the kernel, its shape and
// CUDA's error. For .cu files only.
#pragma once

#include <cuda_runtime.h>

#include <cxxabi.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <utility>

#include "backend/cuda/cuda_check.h"

namespace rf::cuda {

// Threads per block of the builders' kernels: a multiple of 32, so every
// warp is full and full-mask ballots are valid.
constexpr int kBlockSize = 256;

// Blocks of `block_size` threads covering `threads` threads.
constexpr uint32_t blocks_for(uint64_t threads, uint32_t block_size = kBlockSize) {
    return static_cast<uint32_t>((threads + block_size - 1) / block_size);
}

// The grid of a grid-stride kernel: blocks_for(threads), at most
// `max_blocks`; the kernel's threads stride over the rest.
constexpr uint32_t strided_blocks_for(uint64_t threads, uint32_t max_blocks, uint32_t block_size = kBlockSize) {
    return std::min(blocks_for(threads, block_size), max_blocks);
}

// A launch's shape: blocks, threads per block, dynamic shared memory bytes.
struct LaunchShape {
    uint32_t blocks = 0;
    uint32_t threads = kBlockSize;
    size_t shared_bytes = 0;
};

// A launch that failed: the error names the kernel (demangled when it can
// be) and the shape.
[[noreturn]] inline void throw_launch_error(cudaError_t status, const void* kernel, const LaunchShape& shape) {
    const char* symbol = nullptr;
    std::string name = "a kernel";
    if (cudaFuncGetName(&symbol, kernel) == cudaSuccess && symbol != nullptr) {
        int demangled_ok = -1;
        char* demangled = abi::__cxa_demangle(symbol, nullptr, nullptr, &demangled_ok);
        name = demangled_ok == 0 ? demangled : symbol;
        std::free(demangled);
    }
    const std::string call = "launch of " + name + " (" + std::to_string(shape.blocks) + " blocks of " +
                             std::to_string(shape.threads) + " threads, " + std::to_string(shape.shared_bytes) +
                             " bytes of shared memory)";
    throw_cuda_error(status, call.c_str(), __FILE__, __LINE__);
}

// Launches `kernel` with `shape` on `stream` and checks the launch; a
// shape without blocks launches nothing (there is no item).
template <class... Params, class... Args>
void launch_shaped_on(cudaStream_t stream, void (*kernel)(Params...), LaunchShape shape, Args&&... args) {
    if (shape.blocks == 0) return;
    kernel<<<shape.blocks, shape.threads, shape.shared_bytes, stream>>>(std::forward<Args>(args)...);
    const cudaError_t status = cudaGetLastError();
    if (status != cudaSuccess) throw_launch_error(status, reinterpret_cast<const void*>(kernel), shape);
}

// launch_shaped_on the default stream.
template <class... Params, class... Args>
void launch_shaped(void (*kernel)(Params...), LaunchShape shape, Args&&... args) {
    launch_shaped_on(cudaStream_t{}, kernel, shape, std::forward<Args>(args)...);
}

// One thread per item: blocks_for(count) blocks of kBlockSize threads.
template <class... Params, class... Args>
void launch(void (*kernel)(Params...), uint64_t count, Args&&... args) {
    launch_shaped(kernel, LaunchShape{blocks_for(count)}, std::forward<Args>(args)...);
}

}  // namespace rf::cuda
