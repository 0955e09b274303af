// Minimal fixed-width SIMD wrappers for the wide BVH traversals
// (trace/wide_bvh_traversal.h, trace/wide_bvh_packet_traversal.h).
//
// vfloat<4> maps to SSE, vfloat<8> to AVX (compiled in when __AVX2__ is
// defined); any other case falls back to plain arrays, so the traversals build
// everywhere. Semantics follow the SSE instructions exactly, also in the
// fallback: min(a, b) = a < b ? a : b and max(a, b) = a > b ? a : b (a NaN
// first argument yields b, which the slab test relies on), comparisons are
// ordered (false on NaN), and fmadd is a fused multiply-add exactly where
// triangle_intersect.h uses fmaf, so the vectorised watertight test gives
// bit-identical results to the scalar one.
#pragma once

#include <cmath>
#include <cstdint>

#if defined(__SSE2__) || defined(_M_X64)
#include <immintrin.h>
#define RF_SIMD_SSE 1
#endif
#if defined(__AVX2__)
#define RF_SIMD_AVX2 1
#endif

#if defined(__GNUC__)
#define RF_SIMD_INLINE inline __attribute__((always_inline))
#else
#define RF_SIMD_INLINE inline
#endif

namespace rf::simd {

// Generic fallback: N floats, masks are bit sets.
template <int N>
struct vfloat {
    float v[N];
};
template <int N>
struct vmask {
    unsigned bits;
};

template <int N>
RF_SIMD_INLINE vfloat<N> load(const float* p) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) r.v[i] = p[i];
    return r;
}
template <int N>
RF_SIMD_INLINE vfloat<N> set1(float x) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) r.v[i] = x;
    return r;
}
template <int N>
RF_SIMD_INLINE void store(float* p, vfloat<N> a) {
    for (int i = 0; i < N; ++i) p[i] = a.v[i];
}
#define RF_SIMD_GENERIC_BINARY(name, expr)                            \
    template <int N>                                                  \
    RF_SIMD_INLINE vfloat<N> name(vfloat<N> a, vfloat<N> b) {         \
        vfloat<N> r;                                                  \
        for (int i = 0; i < N; ++i) r.v[i] = (expr);                  \
        return r;                                                     \
    }
RF_SIMD_GENERIC_BINARY(add, a.v[i] + b.v[i])
RF_SIMD_GENERIC_BINARY(sub, a.v[i] - b.v[i])
RF_SIMD_GENERIC_BINARY(mul, a.v[i] * b.v[i])
RF_SIMD_GENERIC_BINARY(div, a.v[i] / b.v[i])
RF_SIMD_GENERIC_BINARY(min, a.v[i] < b.v[i] ? a.v[i] : b.v[i])
RF_SIMD_GENERIC_BINARY(max, a.v[i] > b.v[i] ? a.v[i] : b.v[i])
#undef RF_SIMD_GENERIC_BINARY
#define RF_SIMD_GENERIC_COMPARE(name, op)                             \
    template <int N>                                                  \
    RF_SIMD_INLINE vmask<N> name(vfloat<N> a, vfloat<N> b) {          \
        unsigned m = 0;                                               \
        for (int i = 0; i < N; ++i) m |= (a.v[i] op b.v[i]) ? 1u << i : 0u; \
        return {m};                                                   \
    }
RF_SIMD_GENERIC_COMPARE(cmp_le, <=)
RF_SIMD_GENERIC_COMPARE(cmp_ge, >=)
RF_SIMD_GENERIC_COMPARE(cmp_lt, <)
RF_SIMD_GENERIC_COMPARE(cmp_gt, >)
RF_SIMD_GENERIC_COMPARE(cmp_eq, ==)
#undef RF_SIMD_GENERIC_COMPARE
// a * b + c, fused where triangle_intersect.h fuses.
template <int N>
RF_SIMD_INLINE vfloat<N> fmadd(vfloat<N> a, vfloat<N> b, vfloat<N> c) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) {
#if defined(__FMA__)
        r.v[i] = std::fma(a.v[i], b.v[i], c.v[i]);
#else
        r.v[i] = a.v[i] * b.v[i] + c.v[i];
#endif
    }
    return r;
}
template <int N>
RF_SIMD_INLINE vfloat<N> neg(vfloat<N> a) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) r.v[i] = -a.v[i];
    return r;
}
template <int N>
RF_SIMD_INLINE vmask<N> operator&(vmask<N> a, vmask<N> b) { return {a.bits & b.bits}; }
template <int N>
RF_SIMD_INLINE vmask<N> operator|(vmask<N> a, vmask<N> b) { return {a.bits | b.bits}; }
template <int N>
RF_SIMD_INLINE unsigned bits(vmask<N> m) { return m.bits; }

#if defined(RF_SIMD_SSE)
template <>
struct vfloat<4> {
    __m128 v;
};
template <>
struct vmask<4> {
    __m128 v;
};
template <>
RF_SIMD_INLINE vfloat<4> load<4>(const float* p) { return {_mm_load_ps(p)}; }
template <>
RF_SIMD_INLINE vfloat<4> set1<4>(float x) { return {_mm_set1_ps(x)}; }
template <>
RF_SIMD_INLINE void store<4>(float* p, vfloat<4> a) { _mm_store_ps(p, a.v); }
RF_SIMD_INLINE vfloat<4> add(vfloat<4> a, vfloat<4> b) { return {_mm_add_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> sub(vfloat<4> a, vfloat<4> b) { return {_mm_sub_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> mul(vfloat<4> a, vfloat<4> b) { return {_mm_mul_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> div(vfloat<4> a, vfloat<4> b) { return {_mm_div_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> min(vfloat<4> a, vfloat<4> b) { return {_mm_min_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> max(vfloat<4> a, vfloat<4> b) { return {_mm_max_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> cmp_le(vfloat<4> a, vfloat<4> b) { return {_mm_cmple_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> cmp_ge(vfloat<4> a, vfloat<4> b) { return {_mm_cmpge_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> cmp_lt(vfloat<4> a, vfloat<4> b) { return {_mm_cmplt_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> cmp_gt(vfloat<4> a, vfloat<4> b) { return {_mm_cmpgt_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> cmp_eq(vfloat<4> a, vfloat<4> b) { return {_mm_cmpeq_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<4> fmadd(vfloat<4> a, vfloat<4> b, vfloat<4> c) {
#if defined(__FMA__)
    return {_mm_fmadd_ps(a.v, b.v, c.v)};
#else
    return {_mm_add_ps(_mm_mul_ps(a.v, b.v), c.v)};
#endif
}
RF_SIMD_INLINE vfloat<4> neg(vfloat<4> a) { return {_mm_xor_ps(a.v, _mm_set1_ps(-0.0f))}; }
RF_SIMD_INLINE vmask<4> operator&(vmask<4> a, vmask<4> b) { return {_mm_and_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<4> operator|(vmask<4> a, vmask<4> b) { return {_mm_or_ps(a.v, b.v)}; }
RF_SIMD_INLINE unsigned bits(vmask<4> m) { return unsigned(_mm_movemask_ps(m.v)); }
#endif

#if defined(RF_SIMD_AVX2)
template <>
struct vfloat<8> {
    __m256 v;
};
template <>
struct vmask<8> {
    __m256 v;
};
template <>
RF_SIMD_INLINE vfloat<8> load<8>(const float* p) { return {_mm256_load_ps(p)}; }
template <>
RF_SIMD_INLINE vfloat<8> set1<8>(float x) { return {_mm256_set1_ps(x)}; }
template <>
RF_SIMD_INLINE void store<8>(float* p, vfloat<8> a) { _mm256_store_ps(p, a.v); }
RF_SIMD_INLINE vfloat<8> add(vfloat<8> a, vfloat<8> b) { return {_mm256_add_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<8> sub(vfloat<8> a, vfloat<8> b) { return {_mm256_sub_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<8> mul(vfloat<8> a, vfloat<8> b) { return {_mm256_mul_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<8> div(vfloat<8> a, vfloat<8> b) { return {_mm256_div_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<8> min(vfloat<8> a, vfloat<8> b) { return {_mm256_min_ps(a.v, b.v)}; }
RF_SIMD_INLINE vfloat<8> max(vfloat<8> a, vfloat<8> b) { return {_mm256_max_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<8> cmp_le(vfloat<8> a, vfloat<8> b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ)}; }
RF_SIMD_INLINE vmask<8> cmp_ge(vfloat<8> a, vfloat<8> b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ)}; }
RF_SIMD_INLINE vmask<8> cmp_lt(vfloat<8> a, vfloat<8> b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ)}; }
RF_SIMD_INLINE vmask<8> cmp_gt(vfloat<8> a, vfloat<8> b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ)}; }
RF_SIMD_INLINE vmask<8> cmp_eq(vfloat<8> a, vfloat<8> b) { return {_mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ)}; }
RF_SIMD_INLINE vfloat<8> fmadd(vfloat<8> a, vfloat<8> b, vfloat<8> c) {
#if defined(__FMA__)
    return {_mm256_fmadd_ps(a.v, b.v, c.v)};
#else
    return {_mm256_add_ps(_mm256_mul_ps(a.v, b.v), c.v)};
#endif
}
RF_SIMD_INLINE vfloat<8> neg(vfloat<8> a) { return {_mm256_xor_ps(a.v, _mm256_set1_ps(-0.0f))}; }
RF_SIMD_INLINE vmask<8> operator&(vmask<8> a, vmask<8> b) { return {_mm256_and_ps(a.v, b.v)}; }
RF_SIMD_INLINE vmask<8> operator|(vmask<8> a, vmask<8> b) { return {_mm256_or_ps(a.v, b.v)}; }
RF_SIMD_INLINE unsigned bits(vmask<8> m) { return unsigned(_mm256_movemask_ps(m.v)); }
#endif

// Index of the lowest set bit (mask != 0).
RF_SIMD_INLINE int first_bit(unsigned mask) {
#if defined(__GNUC__)
    return __builtin_ctz(mask);
#else
    int i = 0;
    while (!(mask & 1u)) { mask >>= 1; ++i; }
    return i;
#endif
}
RF_SIMD_INLINE int bit_count(unsigned mask) {
#if defined(__GNUC__)
    return __builtin_popcount(mask);
#else
    int n = 0;
    for (; mask; mask &= mask - 1) ++n;
    return n;
#endif
}

}  // namespace rf::simd
