// Products and sums rounded once each, on both compilers. Shared builder
// steps must give the device the CPU's bits: nvcc fuses a * b + c into one
// fused multiply-add (one rounding) unless told otherwise, while the host is
// compiled with -ffp-contract=off (two roundings). Code whose results must
// match across backends computes through these.
#pragma once

#include "rayforge/core/host_device.h"

namespace rf {

RF_HDI float mul_rn(float a, float b) {
#if defined(__CUDA_ARCH__)
    return __fmul_rn(a, b);
#else
    return a * b;
#endif
}

RF_HDI float add_rn(float a, float b) {
#if defined(__CUDA_ARCH__)
    return __fadd_rn(a, b);
#else
    return a + b;
#endif
}

RF_HDI double dmul_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
    return __dmul_rn(a, b);
#else
    return a * b;
#endif
}

RF_HDI double dadd_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
    return __dadd_rn(a, b);
#else
    return a + b;
#endif
}

}  // namespace rf
