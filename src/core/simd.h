// Minimal fixed-width SIMD wrappers for the wide BVH traversals
// (backend/cpu/wide_bvh_traversal.h, backend/cpu/wide_bvh_packet_traversal.h)
// and the binned SAH builder's boxes (accel/bvh/builders/binned_sah.cpp).
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

#include <bit>
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

// Eight unsigned bytes as floats (the 8-bit child boxes of compressed wide
// nodes), and the mask of the nonzero ones among eight bytes.
template <int N>
RF_SIMD_INLINE vfloat<N> load_bytes(const uint8_t* p) {
    vfloat<N> r;
    for (int i = 0; i < N; ++i) r.v[i] = float(p[i]);
    return r;
}
RF_SIMD_INLINE unsigned nonzero_bytes8(const uint8_t* p) {
#if defined(RF_SIMD_SSE)
    const __m128i b = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(p));
    return ~unsigned(_mm_movemask_epi8(_mm_cmpeq_epi8(b, _mm_setzero_si128()))) & 0xFFu;
#else
    unsigned m = 0;
    for (int i = 0; i < 8; ++i) m |= p[i] != 0 ? 1u << i : 0u;
    return m;
#endif
}
#if defined(RF_SIMD_AVX2)
template <>
RF_SIMD_INLINE vfloat<8> load_bytes<8>(const uint8_t* p) {
    const __m128i b = _mm_loadl_epi64(reinterpret_cast<const __m128i*>(p));
    return {_mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(b))};
}
#endif

// Sort keys of the children a ray enters: the entry distance's bit pattern
// with its low three bits replaced by the child's slot, so that one integer
// sort orders the children by distance and still says which is which.
// Distances are >= 0 (they start at the ray's tmin), where float and integer
// order agree; the cleared bits make a key's distance at most 7 ulp smaller
// than the true one, which only makes a later "still closer than the hit?"
// test more permissive. Keys of the lanes not in `mask` sort last.
RF_SIMD_INLINE uint32_t distance_key(float dist, int slot) {
    return (std::bit_cast<uint32_t>(dist) & ~7u) | uint32_t(slot);
}
RF_SIMD_INLINE float key_distance(uint32_t key) {
    return std::bit_cast<float>(key & ~7u);
}
inline constexpr uint32_t kMissedKey = 0x7FFFFFFFu;

// Writes the N keys ascending (generic: insertion sort).
template <int N>
RF_SIMD_INLINE void sort_distance_keys(vfloat<N> dist, unsigned mask, uint32_t* keys) {
    alignas(32) float d[N];
    store<N>(d, dist);
    for (int i = 0; i < N; ++i) {
        const uint32_t key = (mask >> i) & 1u ? distance_key(d[i], i) : kMissedKey;
        int j = i;
        // Signed, as the AVX2 network's min/max: a negative distance (tmin < 0)
        // then sorts before kMissedKey, never after it.
        for (; j > 0 && int32_t(keys[j - 1]) > int32_t(key); --j) keys[j] = keys[j - 1];
        keys[j] = key;
    }
}

#if defined(RF_SIMD_AVX2)
// Eight keys by a bitonic network (six compare-exchange layers, no branches):
// the branchy insertion sort mispredicts on nearly every wide node with three
// or more children hit.
template <int kTakeMax>
RF_SIMD_INLINE __m256i compare_exchange(__m256i v, __m256i partner) {
    return _mm256_blend_epi32(_mm256_min_epi32(v, partner), _mm256_max_epi32(v, partner), kTakeMax);
}
template <>
RF_SIMD_INLINE void sort_distance_keys<8>(vfloat<8> dist, unsigned mask, uint32_t* keys) {
    const __m256i slots = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    const __m256i hit = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(mask)), lane_bits), lane_bits);
    __m256i v = _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), _mm256_castps_si256(dist.v)), slots);
    v = _mm256_blendv_epi8(_mm256_set1_epi32(int(kMissedKey)), v, hit);
    auto swap_pairs = [](__m256i x) { return _mm256_shuffle_epi32(x, 0xB1); };   // partner i ^ 1
    auto swap_quads = [](__m256i x) { return _mm256_shuffle_epi32(x, 0x4E); };   // partner i ^ 2
    auto swap_halves = [](__m256i x) { return _mm256_permute2x128_si256(x, x, 1); };  // partner i ^ 4
    v = compare_exchange<0x66>(v, swap_pairs(v));
    v = compare_exchange<0x3C>(v, swap_quads(v));
    v = compare_exchange<0x5A>(v, swap_pairs(v));
    v = compare_exchange<0xF0>(v, swap_halves(v));
    v = compare_exchange<0xCC>(v, swap_quads(v));
    v = compare_exchange<0xAA>(v, swap_pairs(v));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(keys), v);
}
#endif

// Smallest value over the lanes set in `lanes` (+inf when none is).
template <int N>
RF_SIMD_INLINE float masked_min(vfloat<N> a, unsigned lanes) {
    alignas(32) float v[N];
    store<N>(v, a);
    float m = __builtin_inff();
    for (int i = 0; i < N; ++i) m = (lanes >> i) & 1u && v[i] < m ? v[i] : m;
    return m;
}
#if defined(RF_SIMD_AVX2)
template <>
RF_SIMD_INLINE float masked_min<8>(vfloat<8> a, unsigned lanes) {
    const __m256i lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    const __m256i in = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(lanes)), lane_bits), lane_bits);
    __m256 m = _mm256_blendv_ps(_mm256_set1_ps(__builtin_inff()), a.v, _mm256_castsi256_ps(in));
    m = _mm256_min_ps(m, _mm256_permute2f128_ps(m, m, 1));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, 0x4E));
    m = _mm256_min_ps(m, _mm256_shuffle_ps(m, m, 0xB1));
    return _mm256_cvtss_f32(m);
}
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

// ---- Four lanes for the builders (binned SAH): boxes as (x, y, z, w) ----
// Same semantics in the fallback as on SSE.
#if defined(RF_SIMD_SSE)
RF_SIMD_INLINE vfloat<4> set(float x, float y, float z, float w) { return {_mm_setr_ps(x, y, z, w)}; }
// Lane 3 cleared (+0): it may hold integer bits (denormals, which slow arithmetic down).
RF_SIMD_INLINE vfloat<4> xyz0(vfloat<4> a) {
    return {_mm_and_ps(a.v, _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0)))};
}
// (a[I0], a[I1], a[I2], a[I3]).
template <int I0, int I1, int I2, int I3>
RF_SIMD_INLINE vfloat<4> shuffle(vfloat<4> a) {
    return {_mm_shuffle_ps(a.v, a.v, _MM_SHUFFLE(I3, I2, I1, I0))};
}
template <int I>
RF_SIMD_INLINE float lane(vfloat<4> a) {
    if constexpr (I == 0) return _mm_cvtss_f32(a.v);
    else if constexpr (I == 2) return _mm_cvtss_f32(_mm_movehl_ps(a.v, a.v));
    else return _mm_cvtss_f32(_mm_shuffle_ps(a.v, a.v, _MM_SHUFFLE(I, I, I, I)));
}
// Truncated to integers (values within the int32 range).
RF_SIMD_INLINE void store_truncated(int32_t* p, vfloat<4> a) {
    _mm_storeu_si128(reinterpret_cast<__m128i*>(p), _mm_cvttps_epi32(a.v));
}
#else
RF_SIMD_INLINE vfloat<4> set(float x, float y, float z, float w) { return {{x, y, z, w}}; }
RF_SIMD_INLINE vfloat<4> xyz0(vfloat<4> a) { return {{a.v[0], a.v[1], a.v[2], 0.0f}}; }
template <int I0, int I1, int I2, int I3>
RF_SIMD_INLINE vfloat<4> shuffle(vfloat<4> a) {
    return {{a.v[I0], a.v[I1], a.v[I2], a.v[I3]}};
}
template <int I>
RF_SIMD_INLINE float lane(vfloat<4> a) {
    return a.v[I];
}
RF_SIMD_INLINE void store_truncated(int32_t* p, vfloat<4> a) {
    for (int i = 0; i < 4; ++i) p[i] = static_cast<int32_t>(a.v[i]);
}
#endif

// std::min(a, b) and std::max(a, b) lane by lane (b < a ? b : a and
// a < b ? b : a): min and max with their arguments swapped, so that boxes
// grown with them match scalar std::min / std::max code bit for bit,
// signed zeros included.
template <int N>
RF_SIMD_INLINE vfloat<N> std_min(vfloat<N> a, vfloat<N> b) {
    return min(b, a);
}
template <int N>
RF_SIMD_INLINE vfloat<N> std_max(vfloat<N> a, vfloat<N> b) {
    return max(b, a);
}

}  // namespace rf::simd
