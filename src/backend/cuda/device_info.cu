// Device discovery for `rayforge info --devices` and for checking a
// `--device cuda:N` before anything is uploaded. A failing runtime is
// reported in its own words: a GPU run must be able to tell "no device" from
// "a driver the runtime cannot use" or "a sandbox refusing the device".
#include <cuda_runtime.h>

#include "backend/backends.h"
#include "backend/cuda/cuda_check.h"

namespace rf::cuda {
namespace {

// "13.0" from the runtime's 13000; "none" from 0 (no driver).
std::string version_text(int version) {
    if (version <= 0) return "none";
    return std::to_string(version / 1000) + "." + std::to_string((version % 1000) / 10);
}

// "CALL failed: cudaErrorName: CUDA's message", clearing the sticky error.
std::string runtime_failure(const char* call, cudaError_t status) {
    (void)cudaGetLastError();
    return std::string(call) + " failed: " + cudaGetErrorName(status) + ": " + cudaGetErrorString(status);
}

std::string versions() {
    int driver = 0, runtime = 0;
    (void)cudaDriverGetVersion(&driver);
    (void)cudaRuntimeGetVersion(&runtime);
    return "driver " + version_text(driver) + ", runtime " + version_text(runtime);
}

DeviceInfo describe(int index, const cudaDeviceProp& prop) {
    DeviceInfo info;
    info.index = index;
    info.name = prop.name;
    info.total_memory = prop.totalGlobalMem;
    info.compute_major = prop.major;
    info.compute_minor = prop.minor;
    info.multiprocessors = prop.multiProcessorCount;
    int clock_khz = 0, bus_bits = 0;
    if (cudaDeviceGetAttribute(&clock_khz, cudaDevAttrClockRate, index) == cudaSuccess) info.clock_mhz = clock_khz / 1000;
    if (cudaDeviceGetAttribute(&bus_bits, cudaDevAttrGlobalMemoryBusWidth, index) == cudaSuccess)
        info.memory_bus_bits = bus_bits;
    info.l2_bytes = size_t(prop.l2CacheSize);
    (void)cudaDriverGetVersion(&info.driver_version);
    (void)cudaRuntimeGetVersion(&info.runtime_version);
    size_t free_bytes = 0, total_bytes = 0;
    if (cudaSetDevice(index) == cudaSuccess && cudaMemGetInfo(&free_bytes, &total_bytes) == cudaSuccess)
        info.free_memory = free_bytes;
    (void)cudaGetLastError();
    return info;
}

}  // namespace

bool backend_built() { return true; }

DeviceListing list_devices() {
    DeviceListing listing;
    int count = 0;
    const cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess) {
        listing.error = runtime_failure("cudaGetDeviceCount", status) + " (" + versions() + ")";
        return listing;
    }
    if (count == 0) {
        listing.error = "the CUDA runtime reports 0 devices (" + versions() + ")";
        return listing;
    }
    // Free memory needs each device current in turn; the caller's is restored.
    int current = 0;
    const bool had_current = cudaGetDevice(&current) == cudaSuccess;
    for (int i = 0; i < count; ++i) {
        cudaDeviceProp prop{};
        const cudaError_t queried = cudaGetDeviceProperties(&prop, i);
        if (queried != cudaSuccess) {
            if (!listing.error.empty()) listing.error += "; ";
            listing.error += "cuda:" + std::to_string(i) + ": " + runtime_failure("cudaGetDeviceProperties", queried);
            continue;
        }
        listing.devices.push_back(describe(i, prop));
    }
    if (had_current) (void)cudaSetDevice(current);
    (void)cudaGetLastError();
    return listing;
}

void require_device(int index) {
    int count = 0;
    cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess)
        throw Error("cuda:" + std::to_string(index) + ": no usable CUDA device (" +
                    runtime_failure("cudaGetDeviceCount", status) + ")");
    if (index < 0 || index >= count)
        throw Error("cuda:" + std::to_string(index) + ": no such device (" + std::to_string(count) +
                    " CUDA device" + (count == 1 ? "" : "s") + " found; `rayforge info --devices` lists them)");
}

}  // namespace rf::cuda
