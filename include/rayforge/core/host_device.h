// Marks functions that run on both backends: per-ray code is written once and
// compiled by the host compiler for the CPU backend and by nvcc for the GPU.
#pragma once

#if defined(__CUDACC__)
#define RF_HD __host__ __device__
#define RF_HDI __host__ __device__ __forceinline__
#else
#define RF_HD
#define RF_HDI inline
#endif
