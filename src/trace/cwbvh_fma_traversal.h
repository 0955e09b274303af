// The cwbvh-fma variant (GpuKernel::CwbvhFma) of the compressed 8-wide BVH
// traversal: the same nodes (accel/bvh/layout/cwbvh_layout.h) and the same
// loop (Algorithm 1 of Ylitie, Karras and Laine 2017, "Efficient Incoherent
// Ray Traversal on GPUs Through Compressed Wide BVHs", HPG 2017, shared with
// trace/cwbvh_traversal.h: node and triangle groups, octant order,
// postponement at 20 %), with the node visit as the paper's traversal
// (section 5, on the section 4.1 node) does it instead of a robust slab test
// per dequantised box:
//  - five 16-byte loads per node (__ldg, the read-only path, on the device),
//    fields taken out of the words with shifts;
//  - the ray transformed once per node into the node's quantised frame:
//    s_a = 2^(e_a - 127) * idir_a (exact: a power of two times a float) and
//    o_a = (p_a - org_a) * idir_a, so that a child plane q is at
//    t = fma(q, s_a, o_a), one FMA per plane;
//  - near / far planes of four children at once: one word select per axis on
//    the packed q bytes (hi word first for a negative direction);
//  - the hit bits of four children at once, byte-parallel: is_inner4,
//    bit_index4 = (meta4 ^ (oct_inv4 & inner_mask4)) & 0x1F1F1F1F and
//    child_bits4 = (meta4 >> 5) & 0x07070707; an empty slot (meta 0) has
//    child bits 0, so it needs no branch;
//  - min/max chains that start from tmin / tmax.
//
// Robustness ("never culls a box the ray enters", the box being the
// dequantised one the builder checked to contain the exact box). u = 2^-24.
// With idir = fl(1 / dir), d = fl(p - org), o = fl(d * idir), s exact, the
// computed fl(q * s + o) differs from the exact entry distance of the plane
// B = fl(p + q * step) (the dequantised plane) along the real ray,
// (B - org) / dir, by at most, to first order,
//     4u * 255|s| + 6u|o| + u|org * idir|
// (2u from o, u from idir on both terms, u from the FMA, and u |p + q step|
// |1/dir| for the rounding of B, with |p / dir| <= |o| + |org * idir|). The
// node's planes are therefore moved outward by a per-node pad per axis,
//     pad_a = 2^-20 (|o_a| + 255 |s_a|) + 2^-23 |org_a * idir_a| + 2^-126
// (16u and 2u: twice the bound, which also covers the rounding of o -/+ pad,
// of the pad itself and the second-order terms; 2^-126 covers subnormal
// results, whose errors are absolute, below 2^-140 here). The pad is folded
// into the offsets, near = fma(q, s, o - pad), far = fma(q, s, o + pad), so
// a child costs nothing more: about 4 FFMA / FADD per axis per node.
// Non-finite cases are conservative too: when idir, s, o or the pad is
// infinite (a subnormal direction component, overflow) the pad is +inf or
// NaN, so that axis's near is -inf or NaN and its far +inf or NaN; NaN is
// ignored by the min / max chains (fminf / fmaxf on the device, the
// NaN-keeping forms of trace/bvh_traversal.h on the host), so such an axis
// never culls.
// An exactly zero direction component (axis-parallel rays) would fall in
// that case and cull nothing on its axis, many times the fetches of the slab
// test; it takes an exact integer path instead, only for such rays (one
// branch per node otherwise): the ray stays at org_a, so child slot k is
// entered on that axis iff fl(p + q_lo[k] step) <= org_a <= fl(p + q_hi[k]
// step), i.e. q_lo[k] <= A and q_hi[k] >= B for the integers
// A = floor(x + m), B = ceil(x - m), x = fl(org_a - p) / step, with a margin
// m = 2^-20 |x| + 2^-23 (|p| + |org_a|) / step + 2^-10 above the rounding of
// x and of the dequantised planes (u |x| and u |p + q step| / step); the
// slots that fail have their child bits cleared (one AND per four slots on
// every ray), and the axis's float planes are made neutral (s = 0,
// offsets -inf / +inf: t = -inf / +inf, never NaN). Overflow or NaN in A, B
// resolves to "inside".
// tmax gets the slab test's 1 + 2 gamma(3) (detail::widen_far): a triangle lying
// in a box face must not be culled by its own box once a hit at (almost) its
// distance shrank tmax. Triangles go through the same watertight test on the
// same vertices, so hits are bit-exact with brute force and with the cwbvh
// traversal (wherever that one finds the closest hit: its relative tmax
// slack can miss a triangle whose watertight t lies below its box's entry,
// tests/cwbvh_fma_test.cpp counts such rays; the pad's absolute terms here
// cover the cases seen, though they are not derived for that).
//
// Scheduling support for the persistent kernel (backend/cuda/cwbvh_fma_trace.cu):
// the state is resumable (CwbvhRayState: begin / resume, stepping aside
// between iterations when the Yield policy asks, as AilaLaineDynamicFetchVote
// does for Aila-Laine), and the stack is a policy: a plain array
// (CwbvhLocalStack) or CwbvhSharedTopStack, whose lowest
// kCwbvhSharedStackEntries entries live in shared memory (as the open
// GPU-Raytracer kernel keeps its short stack) and the rest in local memory.
// Counting: the counted variants count node fetches (in nodes_visited and in
// node_fetches), not child box tests, so that they compare with the other
// layouts' node fetches.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "trace/cwbvh_traversal.h"

namespace rf {

// Stack entries of CwbvhSharedTopStack kept in shared memory per thread
// (8 bytes each: 8 KiB per 128-thread block).
inline constexpr int kCwbvhSharedStackEntries = 8;

namespace detail {

// Per-node pad coefficients of the comment above (16u, 2u) and its floor.
inline constexpr float kCwbvhFmaNodePad = 0x1p-20f;
inline constexpr float kCwbvhFmaRayPad = 0x1p-23f;
inline constexpr float kCwbvhFmaPadFloor = 0x1p-126f;

// a * b + c rounded once (FFMA on the device; an FMA instruction or the
// correctly rounded library call on the host: the same result).
RF_HDI float cwbvh_fma(float a, float b, float c) {
#if defined(__CUDA_ARCH__)
    return __fmaf_rn(a, b, c);
#else
    return std::fma(a, b, c);
#endif
}

// Per-ray data of the per-node transform.
struct CwbvhFmaRay {
    Vec3f org;
    Vec3f idir;     // fl(1 / dir): +-inf for a zero component
    Vec3f ray_pad;  // 2^-23 |org * idir| + 2^-126 per axis
    uint32_t octant;      // bit a set: negative direction along a (-0 included)
    uint32_t zero_axes;   // bit a set: dir[a] is +-0

    RF_HDI static CwbvhFmaRay make(const Ray& ray) {
        CwbvhFmaRay r;
        r.org = ray.org;
        r.idir = Vec3f(1.0f / ray.dir.x, 1.0f / ray.dir.y, 1.0f / ray.dir.z);
        for (int a = 0; a < 3; ++a)
            r.ray_pad[a] = cwbvh_fma(kCwbvhFmaRayPad, fabsf(r.org[a] * r.idir[a]), kCwbvhFmaPadFloor);
        r.octant = (r.idir.x < 0.0f ? 1u : 0u) | (r.idir.y < 0.0f ? 2u : 0u) | (r.idir.z < 0.0f ? 4u : 0u);
        r.zero_axes = (ray.dir.x == 0.0f ? 1u : 0u) | (ray.dir.y == 0.0f ? 2u : 0u) | (ray.dir.z == 0.0f ? 4u : 0u);
        return r;
    }
};

// Four little-endian 32-bit words of a node (CUDA's uint4 without CUDA headers).
struct alignas(16) CwbvhWord4 {
    uint32_t x, y, z, w;
};

// The node as five 16-byte words:
//   w[0] = p.x, p.y, p.z, e[0] | e[1] << 8 | e[2] << 16 | imask << 24
//   w[1] = base_index_child, base_index_triangle, meta[0..3], meta[4..7]
//   w[2] = q_lo_x[0..3], q_lo_x[4..7], q_lo_y[0..3], q_lo_y[4..7]
//   w[3] = q_lo_z[0..3], q_lo_z[4..7], q_hi_x[0..3], q_hi_x[4..7]
//   w[4] = q_hi_y[0..3], q_hi_y[4..7], q_hi_z[0..3], q_hi_z[4..7]
struct CwbvhNodeWords {
    CwbvhWord4 w[5];
};
static_assert(sizeof(CwbvhNodeWords) == sizeof(CwbvhNode), "five 16-byte words per node");

RF_HDI CwbvhNodeWords cwbvh_load_node_words(const CwbvhNode* nodes, uint32_t index) {
    CwbvhNodeWords n;
#if defined(__CUDA_ARCH__)
    const uint4* words = reinterpret_cast<const uint4*>(nodes) + 5u * index;
#pragma unroll
    for (int k = 0; k < 5; ++k) {
        const uint4 v = __ldg(words + k);
        n.w[k] = {v.x, v.y, v.z, v.w};
    }
#else
    std::memcpy(&n, nodes + index, sizeof n);
#endif
    return n;
}

// Byte k (0..3) of a word.
RF_HDI uint32_t cwbvh_byte(uint32_t word, int k) { return (word >> (8 * k)) & 0xFFu; }

// The hit-mask bits of four slots at once (one byte each): where a hit
// child's bits go (bit_index4) and which (child_bits4). Per slot this is
// cwbvh_child_hits's: inner (meta bits 3 and 4 set) -> (meta ^ oct_inv) & 31,
// leaf -> meta & 31; bits meta >> 5 (none for an empty slot).
struct CwbvhChildBits4 {
    uint32_t bit_index4;
    uint32_t child_bits4;
};
RF_HDI CwbvhChildBits4 cwbvh_child_bits4(uint32_t meta4, uint32_t oct_inv4) {
    const uint32_t is_inner4 = (meta4 & (meta4 << 1)) & 0x10101010u;
    const uint32_t inner_mask4 = (is_inner4 >> 4) * 0xFFu;  // 0xFF per inner byte (no carries)
    return {(meta4 ^ (oct_inv4 & inner_mask4)) & 0x1F1F1F1Fu, (meta4 >> 5) & 0x07070707u};
}

// Max / min of three plane distances and a bound that ignore NaN distances
// (the bound is never NaN): FMNMX on the device.
RF_HDI float cwbvh_max4(float a, float b, float c, float bound) {
#if defined(__CUDA_ARCH__)
    return fmaxf(fmaxf(a, b), fmaxf(c, bound));
#else
    return max_keep(c, max_keep(b, max_keep(a, bound)));
#endif
}
RF_HDI float cwbvh_min4(float a, float b, float c, float bound) {
#if defined(__CUDA_ARCH__)
    return fminf(fminf(a, b), fminf(c, bound));
#else
    return min_keep(c, min_keep(b, min_keep(a, bound)));
#endif
}

// The node in the ray's frame, per axis: the scaled inverse direction s and
// the padded offsets of the near and far planes (see the top of the file).
struct CwbvhFmaFrame {
    float s[3];
    float o_near[3];
    float o_far[3];
    uint32_t inside4[2];  // per slot byte: 0x07 unless a zero direction axis culls the slot (slots 0-3, 4-7)
};

// NaN-ignoring min / max of two floats (fminf / fmaxf semantics).
RF_HDI float cwbvh_fmin(float a, float b) {
#if defined(__CUDA_ARCH__)
    return fminf(a, b);
#else
    return std::fmin(a, b);
#endif
}
RF_HDI float cwbvh_fmax(float a, float b) {
#if defined(__CUDA_ARCH__)
    return fmaxf(a, b);
#else
    return std::fmax(a, b);
#endif
}

// The exact path of a zero direction component on axis a (see the top of
// the file): clears the child bits of the slots whose slab on that axis does
// not hold org_a and makes the axis's float planes neutral.
RF_HDI void cwbvh_fma_zero_axis(const CwbvhNodeWords& n, const CwbvhFmaRay& r, int a, float p, uint32_t step_bits,
                                CwbvhFmaFrame& f) {
    // 2^(127 - e), exact (2^-127, subnormal, for e = 254).
    const float inv_step = step_bits >= (254u << 23) ? 0x1p-127f : bits_to_float((254u << 23) - step_bits);
    const float x = (r.org[a] - p) * inv_step;
    const float plane_rounding = 0x1p-23f * (fabsf(p) + fabsf(r.org[a]));  // in world units
    const float m = cwbvh_fma(0x1p-20f, fabsf(x), cwbvh_fma(plane_rounding, inv_step, 0x1p-10f));
    // Largest q_lo and smallest q_hi that may hold org_a; NaN gives "any".
    const float a_max = cwbvh_fmax(cwbvh_fmin(floorf(x + m), 255.0f), -1.0f);
    const float b_min = cwbvh_fmin(cwbvh_fmax(ceilf(x - m), 0.0f), 256.0f);
    const uint32_t lo4[2] = {a == 0 ? n.w[2].x : a == 1 ? n.w[2].z : n.w[3].x,
                             a == 0 ? n.w[2].y : a == 1 ? n.w[2].w : n.w[3].y};
    const uint32_t hi4[2] = {a == 0 ? n.w[3].z : a == 1 ? n.w[4].x : n.w[4].z,
                             a == 0 ? n.w[3].w : a == 1 ? n.w[4].y : n.w[4].w};
    for (int half = 0; half < 2; ++half) {
        for (int k = 0; k < 4; ++k) {
            const float q_lo = float(cwbvh_byte(lo4[half], k)), q_hi = float(cwbvh_byte(hi4[half], k));
            if (!(q_lo <= a_max && q_hi >= b_min)) f.inside4[half] &= ~(0xFFu << (8 * k));
        }
    }
    f.s[a] = 0.0f;
    f.o_near[a] = bits_to_float(0xFF800000u);  // -inf
    f.o_far[a] = bits_to_float(0x7F800000u);   // +inf
}
RF_HDI CwbvhFmaFrame cwbvh_fma_frame(const CwbvhNodeWords& n, const CwbvhFmaRay& r) {
    CwbvhFmaFrame f;
    const uint32_t e = n.w[0].w;
    const float p[3] = {bits_to_float(n.w[0].x), bits_to_float(n.w[0].y), bits_to_float(n.w[0].z)};
    const uint32_t step_bits[3] = {(e << 23) & 0x7F800000u, (e << 15) & 0x7F800000u, (e << 7) & 0x7F800000u};
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
    for (int a = 0; a < 3; ++a) {
        const float s = bits_to_float(step_bits[a]) * r.idir[a];  // exact (or +-inf, 0 * inf = NaN never: step > 0)
        const float o = (p[a] - r.org[a]) * r.idir[a];
        const float pad = cwbvh_fma(kCwbvhFmaNodePad, cwbvh_fma(255.0f, fabsf(s), fabsf(o)), r.ray_pad[a]);
        f.s[a] = s;
        f.o_near[a] = o - pad;
        f.o_far[a] = o + pad;
    }
    f.inside4[0] = f.inside4[1] = 0x07070707u;
    if (r.zero_axes != 0) {
        for (int a = 0; a < 3; ++a)
            if (r.zero_axes & (1u << a)) cwbvh_fma_zero_axis(n, r, a, p[a], step_bits[a], f);
    }
    return f;
}

// The node's child hit mask (inner children at 24 + (slot ^ oct_inv), leaf
// triangles at their offsets), four slots per half, no branch per slot.
RF_HDI uint32_t cwbvh_fma_child_hits(const CwbvhNodeWords& n, const CwbvhFmaRay& r, uint32_t oct_inv, float tmin,
                                     float tmax) {
    const CwbvhFmaFrame f = cwbvh_fma_frame(n, r);
    const float far_bound = widen_far(tmax);
    const uint32_t oct_inv4 = oct_inv * 0x01010101u;
    const bool neg_x = (r.octant & 1u) != 0, neg_y = (r.octant & 2u) != 0, neg_z = (r.octant & 4u) != 0;
    uint32_t hits = 0;
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
    for (int half = 0; half < 2; ++half) {
        const uint32_t meta4 = half == 0 ? n.w[1].z : n.w[1].w;
        CwbvhChildBits4 bits = cwbvh_child_bits4(meta4, oct_inv4);
        bits.child_bits4 &= f.inside4[half];
        const uint32_t lo_x = half == 0 ? n.w[2].x : n.w[2].y, hi_x = half == 0 ? n.w[3].z : n.w[3].w;
        const uint32_t lo_y = half == 0 ? n.w[2].z : n.w[2].w, hi_y = half == 0 ? n.w[4].x : n.w[4].y;
        const uint32_t lo_z = half == 0 ? n.w[3].x : n.w[3].y, hi_z = half == 0 ? n.w[4].z : n.w[4].w;
        // Near and far planes of four children: one word select per axis.
        const uint32_t near_x = neg_x ? hi_x : lo_x, far_x = neg_x ? lo_x : hi_x;
        const uint32_t near_y = neg_y ? hi_y : lo_y, far_y = neg_y ? lo_y : hi_y;
        const uint32_t near_z = neg_z ? hi_z : lo_z, far_z = neg_z ? lo_z : hi_z;
#if defined(__CUDA_ARCH__)
#pragma unroll
#endif
        for (int k = 0; k < 4; ++k) {
            const float t_near = cwbvh_max4(cwbvh_fma(float(cwbvh_byte(near_x, k)), f.s[0], f.o_near[0]),
                                            cwbvh_fma(float(cwbvh_byte(near_y, k)), f.s[1], f.o_near[1]),
                                            cwbvh_fma(float(cwbvh_byte(near_z, k)), f.s[2], f.o_near[2]), tmin);
            const float t_far = cwbvh_min4(cwbvh_fma(float(cwbvh_byte(far_x, k)), f.s[0], f.o_far[0]),
                                           cwbvh_fma(float(cwbvh_byte(far_y, k)), f.s[1], f.o_far[1]),
                                           cwbvh_fma(float(cwbvh_byte(far_z, k)), f.s[2], f.o_far[2]), far_bound);
            const uint32_t child_bits = t_near <= t_far ? cwbvh_byte(bits.child_bits4, k) : 0u;
            hits |= child_bits << cwbvh_byte(bits.bit_index4, k);
        }
    }
    return hits;
}

// The node visit of the variant (found by overload from the shared loop,
// detail::cwbvh_resume): counts one node fetch and, with CwbvhCounters, the
// occupied slots as box tests (what the slab-test traversal tests).
template <class Counters>
RF_HDI CwbvhNodeHits cwbvh_visit_node(const CwbvhView& bvh, uint32_t index, const CwbvhFmaRay& r, uint32_t oct_inv,
                                      float tmin, float tmax, Counters* counters) {
    const CwbvhNodeWords n = cwbvh_load_node_words(bvh.nodes, index);
    if constexpr (Counters::kCount) {
        counters->node();
        for (int k = 0; k < 4; ++k) {
            if (cwbvh_byte(n.w[1].z, k) != kCwbvhEmptyMeta) counters->box();
            if (cwbvh_byte(n.w[1].w, k) != kCwbvhEmptyMeta) counters->box();
        }
    }
    return {cwbvh_fma_child_hits(n, r, oct_inv, tmin, tmax), n.w[1].x, n.w[1].y, n.w[0].w >> 24};
}

// TraversalCounters with node fetches (not box tests) as nodes_visited, and
// in node_fetches.
struct CwbvhCountFetches {
    static constexpr bool kCount = true;
    TraversalCounters* c;
    RF_HDI void node() {
        ++c->nodes_visited;
        ++c->node_fetches;
    }
    RF_HDI void box() {}
    RF_HDI void prim() { ++c->prims_tested; }
};

}  // namespace detail

// The traversal stack with its lowest kCwbvhSharedStackEntries entries in
// shared memory (entry i of a thread at shared[i * stride], so that a warp's
// lanes touch consecutive 8-byte words) and the rest in a local array.
// Pushes and pops are at most one per node (about 30 a ray), and most
// traversals stay within the shared part.
struct CwbvhSharedTopStack {
    detail::CwbvhGroup* shared;  // this thread's entry 0
    uint32_t stride;             // threads sharing the array (the block size)
    detail::CwbvhGroup local[kCwbvhTraversalStackSize - kCwbvhSharedStackEntries];

    RF_HDI void store(int i, detail::CwbvhGroup g) {
        if (i < kCwbvhSharedStackEntries) shared[uint32_t(i) * stride] = g;
        else local[i - kCwbvhSharedStackEntries] = g;
    }
    RF_HDI detail::CwbvhGroup load(int i) const {
        return i < kCwbvhSharedStackEntries ? shared[uint32_t(i) * stride] : local[i - kCwbvhSharedStackEntries];
    }
};

// The resumable state of one ray.
using CwbvhFmaRayState = CwbvhRayState<detail::CwbvhFmaRay>;

RF_HDI void cwbvh_fma_begin(const CwbvhView& bvh, const Ray& ray, CwbvhFmaRayState& s) {
    s.box = detail::CwbvhFmaRay::make(ray);
    cwbvh_begin(bvh, ray, s.box.octant, s);
}

// Runs `s` until done (true; s.hit is the answer) or until yield asks it to
// step aside between two iterations (false; call again to go on).
template <bool kAnyHit, class Stack, class Counters, class Postpone, class Yield>
RF_HDI bool cwbvh_fma_resume(const CwbvhView& bvh, CwbvhFmaRayState& s, Stack& stack, Counters* counters,
                             Postpone* postpone, Yield& yield) {
    return detail::cwbvh_resume<kAnyHit>(bvh, s, stack, counters, postpone, yield);
}

namespace detail {

// One ray from start to end, plain stack, no yields.
template <bool kAnyHit, class Counters, class Postpone>
RF_HDI Hit cwbvh_fma_traverse(const CwbvhView& bvh, const Ray& ray, Counters* counters, Postpone* postpone) {
    CwbvhFmaRayState s;
    cwbvh_fma_begin(bvh, ray, s);
    CwbvhLocalStack stack;
    CwbvhNeverYield never;
    cwbvh_resume<kAnyHit>(bvh, s, stack, counters, postpone, never);
    return s.hit;
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; the same hits as cwbvh_intersect.
RF_HDI Hit cwbvh_fma_intersect(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_fma_traverse<false>(bvh, ray, &none, &postpone);
}
RF_HDI bool cwbvh_fma_occluded(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_fma_traverse<true>(bvh, ray, &none, &postpone).found();
}

// Counting variants (accumulated): node fetches as nodes_visited (see the top).
RF_HDI Hit cwbvh_fma_intersect_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountFetches count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_fma_traverse<false>(bvh, ray, &count, &postpone);
}
RF_HDI bool cwbvh_fma_occluded_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountFetches count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_fma_traverse<true>(bvh, ray, &count, &postpone).found();
}
// With CwbvhCounters (fetches, occupied slots tested, triangles), as
// cwbvh_intersect_counted; and with a caller's postponement policy.
RF_HDI Hit cwbvh_fma_intersect_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters) {
    detail::CwbvhCountAll count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_fma_traverse<false>(bvh, ray, &count, &postpone);
}
template <class Postpone>
RF_HDI Hit cwbvh_fma_intersect_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters,
                                       Postpone& postpone) {
    detail::CwbvhCountAll count{&counters};
    return detail::cwbvh_fma_traverse<false>(bvh, ray, &count, &postpone);
}
template <class Postpone>
RF_HDI Hit cwbvh_fma_intersect(const CwbvhView& bvh, const Ray& ray, Postpone& postpone) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_fma_traverse<false>(bvh, ray, &none, &postpone);
}
template <class Postpone>
RF_HDI bool cwbvh_fma_occluded(const CwbvhView& bvh, const Ray& ray, Postpone& postpone) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_fma_traverse<true>(bvh, ray, &none, &postpone).found();
}

}  // namespace rf
