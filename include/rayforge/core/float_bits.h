// Bit casts between float and uint32_t for code compiled for both backends:
// CUDA's intrinsics on the device, memcpy on the host (compiled to a move).
// GPU layouts use them to keep indices in float lanes and floats in integer words.
#pragma once

#include <cstdint>
#include <cstring>

#include "rayforge/core/host_device.h"

namespace rf {

RF_HDI uint32_t float_to_bits(float f) {
#if defined(__CUDA_ARCH__)
    return __float_as_uint(f);
#else
    uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
#endif
}

RF_HDI float bits_to_float(uint32_t u) {
#if defined(__CUDA_ARCH__)
    return __uint_as_float(u);
#else
    float f;
    std::memcpy(&f, &u, sizeof f);
    return f;
#endif
}

}  // namespace rf
