// CUB's two-call pattern as one call. A CUB device algorithm given a null
// scratch pointer only reports the scratch bytes it needs; cub_run asks,
// grows `scratch` (a DeviceBuffer, so a metered one counts the growth) and
// runs it. `call` is the algorithm with its scratch left open:
//   cub_run(scratch, [&](void* temp, size_t& bytes) {
//       return cub::DeviceScan::InclusiveSum(temp, bytes, in, out, n);
//   });
// cub_reserve only asks and grows: the allocation then happens before a
// timed stage, and the cub_run inside it finds the room already there.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "backend/cuda/cuda_check.h"
#include "backend/cuda/device_buffer.h"

namespace rf::cuda {

// Grows `scratch` to what `call` needs (at least 1 byte: CUB only reports
// when given a null pointer) and returns the bytes asked for.
template <class Call>
size_t cub_reserve(DeviceBuffer<uint8_t>& scratch, Call&& call) {
    size_t bytes = 0;
    RF_CUDA_CHECK(call(nullptr, bytes));
    scratch.reserve(std::max<size_t>(bytes, 1));
    return bytes;
}

template <class Call>
void cub_run(DeviceBuffer<uint8_t>& scratch, Call&& call) {
    size_t bytes = cub_reserve(scratch, call);
    RF_CUDA_CHECK(call(static_cast<void*>(scratch.data()), bytes));
}

}  // namespace rf::cuda
