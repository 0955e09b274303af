// Device discovery for `rayforge info --devices` and for checking a
// `--device cuda:N` before anything is uploaded.
#include <cuda_runtime.h>

#include "backend/cuda/cuda_check.h"
#include "rayforge/backend/cuda.h"

namespace rf::cuda {

std::vector<DeviceInfo> list_devices() {
    std::vector<DeviceInfo> devices;
    int count = 0;
    if (cudaGetDeviceCount(&count) != cudaSuccess) {
        (void)cudaGetLastError();
        return devices;
    }
    // Free memory needs each device current in turn; the caller's is restored.
    int current = 0;
    const bool had_current = cudaGetDevice(&current) == cudaSuccess;
    int driver = 0, runtime = 0;
    (void)cudaDriverGetVersion(&driver);
    (void)cudaRuntimeGetVersion(&runtime);
    for (int i = 0; i < count; ++i) {
        cudaDeviceProp prop{};
        if (cudaGetDeviceProperties(&prop, i) != cudaSuccess) {
            (void)cudaGetLastError();
            continue;
        }
        DeviceInfo info;
        info.index = i;
        info.name = prop.name;
        info.total_memory = prop.totalGlobalMem;
        info.compute_major = prop.major;
        info.compute_minor = prop.minor;
        info.multiprocessors = prop.multiProcessorCount;
        int clock_khz = 0, bus_bits = 0;
        if (cudaDeviceGetAttribute(&clock_khz, cudaDevAttrClockRate, i) == cudaSuccess) info.clock_mhz = clock_khz / 1000;
        if (cudaDeviceGetAttribute(&bus_bits, cudaDevAttrGlobalMemoryBusWidth, i) == cudaSuccess)
            info.memory_bus_bits = bus_bits;
        info.l2_bytes = size_t(prop.l2CacheSize);
        info.driver_version = driver;
        info.runtime_version = runtime;
        size_t free_bytes = 0, total_bytes = 0;
        if (cudaSetDevice(i) == cudaSuccess && cudaMemGetInfo(&free_bytes, &total_bytes) == cudaSuccess)
            info.free_memory = free_bytes;
        (void)cudaGetLastError();
        devices.push_back(info);
    }
    if (had_current) (void)cudaSetDevice(current);
    (void)cudaGetLastError();
    return devices;
}

std::string device_unavailable_reason() {
    int count = 0;
    cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess) {
        (void)cudaGetLastError();
        return cudaGetErrorString(status);
    }
    return count == 0 ? "no CUDA device found" : "";
}

void require_device(int index) {
    int count = 0;
    cudaError_t status = cudaGetDeviceCount(&count);
    if (status != cudaSuccess) {
        (void)cudaGetLastError();
        throw Error("cuda:" + std::to_string(index) + ": no usable CUDA device (" + cudaGetErrorString(status) + ")");
    }
    if (index < 0 || index >= count)
        throw Error("cuda:" + std::to_string(index) + ": no such device (" + std::to_string(count) +
                    " CUDA device" + (count == 1 ? "" : "s") + " found; `rayforge info --devices` lists them)");
}

}  // namespace rf::cuda
