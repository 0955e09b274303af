// Where work runs: the CPU backend or one CUDA device. These names and types
// need no CUDA toolkit, so the CLI, the bench and scene files parse
// `--device` the same way whether or not the CUDA backend was built.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace rf {

struct Device {
    enum class Kind : uint8_t { Cpu, Cuda };
    Kind kind = Kind::Cpu;
    int index = 0;  // CUDA device ordinal (0 = the first device)

    [[nodiscard]] bool is_cuda() const { return kind == Kind::Cuda; }
    bool operator==(const Device&) const = default;
};

// "cpu", "cuda" (= cuda:0) or "cuda:N"; throws rf::Error otherwise.
Device parse_device(const std::string& name);
std::string to_string(const Device& device);

// The GPU traversal kernels (rf::cuda::DeviceTracer), one per structure the
// seeds compare:
//   bvh2            the canonical binary BVH, one thread per ray (the CPU's own traversal code)
//   aila-laine      node pairs with persistent "while-while" threads (Aila and Laine 2009)
//   cwbvh           the compressed 8-wide BVH (Ylitie, Karras and Laine 2017)
//   kd-short-stack  kd-tree, short stack with restart fallback (Horn et al. 2007; seed 002)
//   kd-restart      kd-tree, kd-restart (Foley and Sugerman 2005; seed 002)
//   grid            uniform grid, 3D-DDA (seeds 001, 002)
//   grid-proximity  uniform grid with proximity clouds (seed 001)
enum class GpuKernel : uint8_t { Bvh2, AilaLaine, Cwbvh, KdShortStack, KdRestart, Grid, ProximityGrid };

GpuKernel parse_gpu_kernel(const std::string& name);  // throws rf::Error for an unknown name
std::string to_string(GpuKernel kernel);
std::vector<GpuKernel> all_gpu_kernels();
// The kernel the renderers and the bench use unless told otherwise.
inline constexpr GpuKernel kDefaultGpuKernel = GpuKernel::Cwbvh;

// Whether this build of rayforge contains the CUDA backend (nvcc was found at configure time).
bool cuda_backend_built();

}  // namespace rf
