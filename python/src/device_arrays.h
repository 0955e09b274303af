// CUDA device arrays from Python, for the device batches (World /
// Accel ::intersect_on_device): any object exposing
// __cuda_array_interface__ (versions 2 and 3: CuPy, Numba, PyTorch, Warp)
// or __dlpack__ (PyTorch, CuPy, JAX, Warp), read and written in place in
// the engine's layouts, so rays and answers never pass through the host:
//   rays      (n, 8) float32: ox, oy, oz, tmin, dx, dy, dz, tmax (rf::Ray)
//   hits      (n, 4) 4-byte elements: t, u, v, prim (rf::Hit; prim is the
//             uint32 bit pattern of the last column, 0xFFFFFFFF on a miss)
//   occluded  (n,) uint8 or bool
// C-contiguous only. Errors name the argument: TypeError for an object
// that is no device array or has the wrong element type, ValueError for a
// wrong shape, strides, a read-only output or memory on the CPU.
#pragma once

#include <pybind11/pybind11.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace rf {
class World;
}

namespace rf::py {

namespace pyb = pybind11;

struct DeviceArray {
    void* data = nullptr;
    std::vector<int64_t> shape;
    char kind = 0;      // 'f' float, 'u' unsigned, 'i' signed, 'b' bool
    int item_bytes = 0;
    std::optional<intptr_t> stream;   // __cuda_array_interface__ v3: the stream its producer wrote on
    std::shared_ptr<void> owner;      // a consumed DLPack tensor, released (its deleter called) with the last copy
};

// `value` as a C-contiguous CUDA device array (`writable`: an output).
DeviceArray device_array(const pyb::handle& value, const char* name, bool writable);

// The closest hits (hits set) or any hits (occluded set) of device rays on
// `world`'s device, on `stream` (None: the rays' producer stream when
// __cuda_array_interface__ names one, else the default stream); the GIL is
// released while the device works.
void trace_device_arrays(const World& world, const pyb::handle& rays, const pyb::handle* hits,
                         const pyb::handle* occluded, const std::optional<intptr_t>& stream);

// rayforge._DeviceBuffer (builds with CUDA only): device memory for the
// tests and examples, exposing both interfaces.
void bind_device_buffer(pyb::module_& m);

}  // namespace rf::py
