// Where work runs: the CPU backend or one CUDA device. These names and types
// need no CUDA toolkit, so the CLI, the bench and scene files parse
// `--device` the same way whether or not the CUDA backend was built.
#pragma once

#include <cstddef>
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

// The GPU traversal kernels, one per structure (BuildOptions::gpu_kernel on
// a CUDA device):
//   bvh2            the canonical binary BVH, one thread per ray (the CPU's own traversal code)
//   aila-laine      node pairs with persistent "while-while" threads (Aila and Laine 2009)
//   aila-laine-fma  the same, the ray kept in registers and the box test in FMA min/max form
//                   (a variant until a device measures it against aila-laine)
//   cwbvh           the compressed 8-wide BVH (Ylitie, Karras and Laine 2017)
//   cwbvh-fma       the same nodes traced as the paper does: the ray transformed once per node into
//                   its quantised frame, octant-ordered child masks, persistent threads (a variant
//                   until a device measures it against cwbvh)
//   kd-short-stack  kd-tree, short stack with restart fallback (Horn et al. 2007)
//   kd-restart      kd-tree, kd-restart (Foley and Sugerman 2005)
//   grid            uniform grid, 3D-DDA (Amanatides and Woo 1987)
//   grid-proximity  uniform grid with proximity clouds (Bogolepov et al.)
enum class GpuKernel : uint8_t {
    Bvh2, AilaLaine, Cwbvh, KdShortStack, KdRestart, Grid, ProximityGrid, AilaLaineFma, CwbvhFma
};

GpuKernel parse_gpu_kernel(const std::string& name);  // throws rf::Error for an unknown name
std::string to_string(GpuKernel kernel);
std::vector<GpuKernel> all_gpu_kernels();
// The kernel the renderers and the bench use unless told otherwise: the
// fastest on Sponza's diffuse rays where a device last measured them
// (docs/gpu.md; H200, 2026-11-27: aila-laine 807 Mrays/s, cwbvh 606).
inline constexpr GpuKernel kDefaultGpuKernel = GpuKernel::AilaLaine;

// Whether this build of rayforge contains the CUDA backend (nvcc was found at configure time).
bool cuda_backend_built();

struct DeviceInfo {
    int index = 0;             // the N of cuda:N
    std::string name;
    size_t total_memory = 0;
    size_t free_memory = 0;
    int compute_major = 0, compute_minor = 0;
    int multiprocessors = 0;
    int clock_mhz = 0;         // SM clock
    int memory_bus_bits = 0;
    size_t l2_bytes = 0;
    int driver_version = 0;    // e.g. 13000 for CUDA 13.0
    int runtime_version = 0;
};

// The CUDA devices this process can use and, when there are none (or one
// could not be queried), why, in the runtime's own words, e.g.
// "cudaGetDeviceCount failed: cudaErrorNoDevice: no CUDA-capable device is
// detected (driver none, runtime 13.0)", or that this build has no CUDA
// backend. Never throws.
struct DeviceListing {
    std::vector<DeviceInfo> devices;
    std::string error;  // "" when every device was listed
};
DeviceListing list_cuda_devices();

// Throws rf::Error saying why `device` cannot be used (a build without the
// CUDA backend, no driver, no such device); the CPU always can.
void require_device(const Device& device);

// The resources of one GPU trace kernel as compiled for the device (CUDA's
// function attributes) and the occupancy of the launch shape its tracer uses.
struct GpuKernelResources {
    std::string kernel;             // which launch: e.g. "aila-laine closest (persistent)"
    int registers = 0;              // per thread
    size_t local_bytes = 0;         // per thread: spills and the stack frame (local memory)
    size_t shared_bytes = 0;        // shared memory per block: static, plus the launch's dynamic
    int max_threads_per_block = 0;  // what the compiled kernel allows
    int block_size = 0;             // what the tracer launches
    int blocks_per_sm = 0;          // resident blocks per multiprocessor at that block size
    double occupancy = 0.0;         // resident threads / the multiprocessor's maximum, in [0, 1]
};
// The closest-hit and any-hit launches of `kernel` on CUDA device `device`
// (the bench's resource lines); empty for a kernel whose launches are not
// listed yet. Throws rf::Error as require_device does, and for the CPU.
std::vector<GpuKernelResources> gpu_kernel_resources(GpuKernel kernel, const Device& device);

}  // namespace rf
