// Single-ray closest-hit and any-hit traversal of the 4- and 8-wide BVHs
// (accel/bvh/layout/wide_bvh.h), after Wald, Benthin and Boulos 2008 and
// Fuetterling et al. 2017 ("Accelerated single ray tracing for wide vector
// units"): one SIMD slab test checks all N child boxes of a node, the hit
// children are visited nearest first (closest hit; any hit orders only
// pairs), the others wait on a stack together with their entry distance so
// that they are skipped once a closer hit is known. Leaf triangles are tested four at a time with a vectorised copy of
// the watertight test (Woop, Benthin and Wald 2013) that performs exactly the
// operations of trace/triangle_intersect.h, so t, u and v are bit-identical
// to the scalar test.
//
// The slab test is Ize's robust one ("Robust BVH Ray Traversal", JCGT 2013)
// as in trace/bvh_traversal.h: (plane - origin) * (1 / dir), with the far
// distances enlarged so that rounding never culls a box the ray enters; the
// near and far planes are chosen once per ray from the direction's signs.
#pragma once

#include <cmath>
#include <cstdint>

#include "accel/bvh/layout/wide_bvh.h"
#include "rayforge/math/ray.h"
#include "trace/bvh_traversal.h"
#include "core/simd.h"
#include "trace/triangle_intersect.h"

namespace rf {

template <int N>
struct WideBvhView {
    const WideNode<N>* nodes = nullptr;
    const TrianglePack* packs = nullptr;
    uint32_t node_count = 0;
    float coord_scale = 1.0f;  // largest |coordinate| of the scene (WideBvh::coord_scale)
};

namespace wide_detail {

// Prefetching the children pushed on the stack costs about 6% more
// instructions but pays off where the tree outgrows the caches (dragon).
inline constexpr bool kPrefetch = true;

// The far distances use 1 / dir pre-multiplied by this, which covers the
// rounding of the subtraction, the reciprocal, the product and the scaling
// itself (1 + 2 gamma(4); Ize 2013 uses 1 + 2 gamma(3) for three roundings).
inline constexpr float kFarRcpScale = 1.0f + 2.0f * (4.0f * 0x1p-24f) / (1.0f - 4.0f * 0x1p-24f);

// That relative scaling narrows a negative far distance (a box behind the
// origin, met only with tmin < 0). A far plane below tmin misses the box
// anyway, so the planes that matter have |t| <= T = -tmin: their deficit is
// below (8u + 4u) T (the scale, four roundings; u = 2^-24), the near
// planes' rounding adds 3u T. An absolute pad of 32u T on the far planes
// (at least FLT_MIN, for subnormal results) covers that and its own
// rounding. Zero for tmin >= 0: those rays trace exactly as before.
inline float far_plane_pad(float tmin) {
    const float pad = -tmin * 0x1p-19f;
    return tmin < 0.0f ? (pad > 0x1p-126f ? pad : 0x1p-126f) : 0.0f;
}

// The stack holds at most N - 1 entries per level of the wide tree.
template <int N>
inline constexpr int kStackSize = kBvhMaxDepth * (N - 1) + N;

// Per-ray constants of the N-wide slab test. With FMA the slab distance
// (plane - origin) * rcp becomes one fused plane * rcp - origin * rcp, as in
// Embree. The rounding of origin * rcp is an absolute error (up to half an
// ulp of it), so it is covered by an absolute margin folded into the
// constant: the near constant is enlarged and the far one reduced by 2^-22
// of their magnitude, which only ever widens the boxes; the relative errors
// are covered by the far reciprocal scale as before (Ize 2013). Zero (or
// tiny) direction components would make origin * rcp infinite or NaN, so
// they are replaced by a tiny signed value small enough that a box is missed
// on that axis only if the ray is within 2^-100 times the scene's size of the
// slab over its whole length, yet large enough that plane * rcp stays finite.
template <int N>
struct BoxRay {
#if defined(__FMA__)
    simd::vfloat<N> neg_org_near[3];  // -(origin * rcp) - margin
    simd::vfloat<N> neg_org_far[3];   // -(origin * rcp_far) + margin
#else
    simd::vfloat<N> org[3];
    simd::vfloat<N> far_pad = simd::set1<N>(0.0f);  // far_plane_pad(tmin), added to t_far per node
#endif
    simd::vfloat<N> rcp_near[3];
    simd::vfloat<N> rcp_far[3];
    int near_row[3];  // rows of WideNode::bounds holding the entry (near) planes
    int far_row[3];

    static RF_SIMD_INLINE BoxRay make(const Ray& ray, float coord_scale) {
        BoxRay r;
        for (int axis = 0; axis < 3; ++axis) {
            const float o = ray.org[axis];
#if defined(__FMA__)
            float d = ray.dir[axis];
            float magnitude = std::fabs(o) > coord_scale ? std::fabs(o) : coord_scale;  // not fmax: a libm call
            magnitude = magnitude > 0x1p-20f ? magnitude : 0x1p-20f;
            const float tiny = magnitude * 0x1p-100f;
            if (std::fabs(d) < tiny) d = std::copysign(tiny, d);
            const float rcp = 1.0f / d;
#else
            (void)coord_scale;  // only the FMA form shifts the planes by a scale-relative margin
            const float rcp = 1.0f / ray.dir[axis];
#endif
            const int negative = rcp < 0.0f ? 1 : 0;
            const float rcp_far = rcp * kFarRcpScale;
#if defined(__FMA__)
            const float c_near = o * rcp;
            const float c_far = o * rcp_far;
            r.neg_org_near[axis] = simd::set1<N>(-(c_near + (std::fabs(c_near) * 0x1p-22f + 0x1p-126f)));
            r.neg_org_far[axis] = simd::set1<N>(-(c_far - (std::fabs(c_far) * 0x1p-22f + 0x1p-126f)));
#else
            r.org[axis] = simd::set1<N>(o);
#endif
            r.rcp_near[axis] = simd::set1<N>(rcp);
            r.rcp_far[axis] = simd::set1<N>(rcp_far);
            r.near_row[axis] = 2 * axis + negative;
            r.far_row[axis] = 2 * axis + 1 - negative;
        }
        if (ray.tmin < 0.0f) {
            const simd::vfloat<N> pad = simd::set1<N>(far_plane_pad(ray.tmin));
#if defined(__FMA__)
            for (int axis = 0; axis < 3; ++axis) r.neg_org_far[axis] = simd::add(r.neg_org_far[axis], pad);  // no cost per node
#else
            r.far_pad = pad;
#endif
        }
        return r;
    }
};

// Slab test of N boxes given as bounds[2 * axis + side][box] (side 0 = lo,
// 1 = hi: WideNode::bounds); bit c of the result is set when the ray enters
// box c within [tmin, tmax]. `t_near` receives the entry distances.
template <int N>
RF_SIMD_INLINE unsigned box_hits(const float (&bounds)[6][N], const BoxRay<N>& r, simd::vfloat<N> tmin,
                                 simd::vfloat<N> tmax_far, simd::vfloat<N>& t_near) {
    using namespace simd;
#if defined(__FMA__)
    const vfloat<N> x0 = fmadd(load<N>(bounds[r.near_row[0]]), r.rcp_near[0], r.neg_org_near[0]);
    const vfloat<N> y0 = fmadd(load<N>(bounds[r.near_row[1]]), r.rcp_near[1], r.neg_org_near[1]);
    const vfloat<N> z0 = fmadd(load<N>(bounds[r.near_row[2]]), r.rcp_near[2], r.neg_org_near[2]);
    const vfloat<N> x1 = fmadd(load<N>(bounds[r.far_row[0]]), r.rcp_far[0], r.neg_org_far[0]);
    const vfloat<N> y1 = fmadd(load<N>(bounds[r.far_row[1]]), r.rcp_far[1], r.neg_org_far[1]);
    const vfloat<N> z1 = fmadd(load<N>(bounds[r.far_row[2]]), r.rcp_far[2], r.neg_org_far[2]);
#else
    const vfloat<N> x0 = mul(sub(load<N>(bounds[r.near_row[0]]), r.org[0]), r.rcp_near[0]);
    const vfloat<N> y0 = mul(sub(load<N>(bounds[r.near_row[1]]), r.org[1]), r.rcp_near[1]);
    const vfloat<N> z0 = mul(sub(load<N>(bounds[r.near_row[2]]), r.org[2]), r.rcp_near[2]);
    const vfloat<N> x1 = mul(sub(load<N>(bounds[r.far_row[0]]), r.org[0]), r.rcp_far[0]);
    const vfloat<N> y1 = mul(sub(load<N>(bounds[r.far_row[1]]), r.org[1]), r.rcp_far[1]);
    const vfloat<N> z1 = mul(sub(load<N>(bounds[r.far_row[2]]), r.org[2]), r.rcp_far[2]);
#endif
    // Operand order matters: a NaN slab distance (origin on the plane of a
    // zero direction component, without FMA) must leave the bound unchanged.
    t_near = max(z0, max(y0, max(x0, tmin)));
#if defined(__FMA__)
    const vfloat<N> t_far = min(z1, min(y1, min(x1, tmax_far)));
#else
    const vfloat<N> t_far = add(min(z1, min(y1, min(x1, tmax_far))), r.far_pad);
#endif
    return bits(cmp_le(t_near, t_far));
}

// The same test on a node's N child boxes.
template <int N>
RF_SIMD_INLINE unsigned box_hits(const WideNode<N>& node, const BoxRay<N>& r, simd::vfloat<N> tmin,
                                 simd::vfloat<N> tmax_far, simd::vfloat<N>& t_near) {
    return box_hits(node.bounds, r, tmin, tmax_far, t_near);
}

// Starts loading a child the ray will visit later (its node's four cache
// lines, or its first triangle pack), so the pop does not wait on memory.
template <int N>
RF_SIMD_INLINE void prefetch_ref(const WideBvhView<N>& bvh, uint32_t ref) {
#if defined(RF_SIMD_SSE)
    const char* p = wide_is_leaf(ref) ? reinterpret_cast<const char*>(&bvh.packs[wide_leaf_first_pack(ref)])
                                      : reinterpret_cast<const char*>(&bvh.nodes[ref]);
    if (wide_is_leaf(ref)) {
        // A pack is 160 bytes, 16-byte aligned: up to four lines.
        _mm_prefetch(p, _MM_HINT_T0);
        _mm_prefetch(p + 64, _MM_HINT_T0);
        _mm_prefetch(p + 128, _MM_HINT_T0);
        _mm_prefetch(p + sizeof(TrianglePack) - 1, _MM_HINT_T0);
    } else {
        for (size_t i = 0; i < sizeof(WideNode<N>); i += 64) _mm_prefetch(p + i, _MM_HINT_T0);
    }
#else
    (void)bvh;
    (void)ref;
#endif
}

// Per-ray constants of the packed watertight test.
struct PackRay {
    WatertightRay scalar;
    simd::vfloat<4> org_x, org_y, org_z;      // origin in the permuted frame
    simd::vfloat<4> neg_sx, neg_sy, sz;
    int kx, ky, kz;

    static RF_SIMD_INLINE PackRay make(const Ray& ray) {
        PackRay r;
        r.scalar = WatertightRay::make(ray);
        r.kx = r.scalar.kx;
        r.ky = r.scalar.ky;
        r.kz = r.scalar.kz;
        r.org_x = simd::set1<4>(ray.org[r.kx]);
        r.org_y = simd::set1<4>(ray.org[r.ky]);
        r.org_z = simd::set1<4>(ray.org[r.kz]);
        r.neg_sx = simd::set1<4>(-r.scalar.sx);
        r.neg_sy = simd::set1<4>(-r.scalar.sy);
        r.sz = simd::set1<4>(r.scalar.sz);
        return r;
    }
};

// Lanes whose edge functions hit exactly 0 are decided by the scalar test,
// which recomputes them in double (rare: rays through edges and vertices).
[[gnu::noinline]] inline unsigned intersect_pack_exact_lanes(const PackRay& r, const TrianglePack& p,
                                                             unsigned lanes, float tmin, float tmax, float* t,
                                                             float* u, float* v) {
    unsigned hits = 0;
    for (; lanes; lanes &= lanes - 1) {
        const int lane = simd::first_bit(lanes);
        const Triangle tri{Vec3f(p.v[0][0][lane], p.v[0][1][lane], p.v[0][2][lane]),
                           Vec3f(p.v[1][0][lane], p.v[1][1][lane], p.v[1][2][lane]),
                           Vec3f(p.v[2][0][lane], p.v[2][1][lane], p.v[2][2][lane])};
        TriangleHit h;
        if (intersect_triangle(r.scalar, tri, tmin, tmax, h)) {
            t[lane] = h.t;
            u[lane] = h.u;
            v[lane] = h.v;
            hits |= 1u << lane;
        }
    }
    return hits;
}

// a * b - c * d, as detail::difference_of_products computes it.
RF_SIMD_INLINE simd::vfloat<4> difference_of_products(simd::vfloat<4> a, simd::vfloat<4> b, simd::vfloat<4> c,
                                                      simd::vfloat<4> d) {
    using namespace simd;
#if defined(__FMA__)
    const vfloat<4> cd = mul(c, d);
    const vfloat<4> error = fmadd(neg(c), d, cd);
    const vfloat<4> dop = fmadd(a, b, neg(cd));
    return add(dop, error);
#else
    return sub(mul(a, b), mul(c, d));
#endif
}

// The watertight test of triangle_intersect.h on four triangles at once.
// Returns the lanes hit with tmin <= t <= tmax and fills t, u, v there.
RF_SIMD_INLINE unsigned intersect_pack(const PackRay& r, const TrianglePack& p, float tmin, float tmax, float* t_out,
                                       float* u_out, float* v_out) {
    using namespace simd;
    using V = vfloat<4>;
    const V a_x = sub(load<4>(p.v[0][r.kx]), r.org_x);
    const V a_y = sub(load<4>(p.v[0][r.ky]), r.org_y);
    const V a_z = sub(load<4>(p.v[0][r.kz]), r.org_z);
    const V b_x = sub(load<4>(p.v[1][r.kx]), r.org_x);
    const V b_y = sub(load<4>(p.v[1][r.ky]), r.org_y);
    const V b_z = sub(load<4>(p.v[1][r.kz]), r.org_z);
    const V c_x = sub(load<4>(p.v[2][r.kx]), r.org_x);
    const V c_y = sub(load<4>(p.v[2][r.ky]), r.org_y);
    const V c_z = sub(load<4>(p.v[2][r.kz]), r.org_z);
    // shear_coordinate(a, s, b) = a - s * b (fused where the scalar test fuses).
    const V ax = fmadd(r.neg_sx, a_z, a_x);
    const V ay = fmadd(r.neg_sy, a_z, a_y);
    const V bx = fmadd(r.neg_sx, b_z, b_x);
    const V by = fmadd(r.neg_sy, b_z, b_y);
    const V cx = fmadd(r.neg_sx, c_z, c_x);
    const V cy = fmadd(r.neg_sy, c_z, c_y);
    const V u = difference_of_products(cx, by, cy, bx);
    const V v = difference_of_products(ax, cy, ay, cx);
    const V w = difference_of_products(bx, ay, by, ax);
    const V zero = set1<4>(0.0f);
    const unsigned exact_lanes = bits(cmp_eq(u, zero) | cmp_eq(v, zero) | cmp_eq(w, zero));
    const unsigned outside =
        bits((cmp_lt(u, zero) | cmp_lt(v, zero) | cmp_lt(w, zero)) & (cmp_gt(u, zero) | cmp_gt(v, zero) | cmp_gt(w, zero)));
    unsigned candidates = ~(outside | exact_lanes) & 15u;
    unsigned hits = 0;
    if (candidates) {
        const V det = add(add(u, v), w);
        const V az = mul(r.sz, a_z);
        const V bz = mul(r.sz, b_z);
        const V cz = mul(r.sz, c_z);
#if defined(__FMA__)
        const V scaled_t = fmadd(u, az, fmadd(v, bz, mul(w, cz)));
#else
        const V scaled_t = add(add(mul(u, az), mul(v, bz)), mul(w, cz));
#endif
        const V inv_det = div(set1<4>(1.0f), det);
        const V t = mul(scaled_t, inv_det);
        // det == 0: degenerate or parallel; NaN t (empty or zero-area slots) fails the range test.
        hits = candidates & ~bits(cmp_eq(det, zero)) & bits(cmp_ge(t, set1<4>(tmin)) & cmp_le(t, set1<4>(tmax)));
        if (hits) {
            store<4>(t_out, t);
            store<4>(u_out, mul(v, inv_det));
            store<4>(v_out, mul(w, inv_det));
        }
    }
    if (exact_lanes) [[unlikely]] {
        hits |= intersect_pack_exact_lanes(r, p, exact_lanes, tmin, tmax, t_out, u_out, v_out);
    }
    return hits;
}

RF_SIMD_INLINE uint32_t pack_reference_count(const TrianglePack& p) {
    uint32_t n = 0;
    for (int lane = 0; lane < kTrianglePackWidth; ++lane) n += p.prim[lane] != kInvalidId ? 1u : 0u;
    return n;
}

struct StackItem {
    uint32_t ref;
    float dist;  // where the ray enters the child's box
};

// tmax widened for the box tests: with tmin >= 0 (!kBehind) tmax is >= 0
// (or the interval empty), where widen_far is the plain product.
template <bool kBehind>
RF_SIMD_INLINE float widen_tmax(float t) {
    if constexpr (kBehind) return detail::widen_far(t);
    else return t * detail::kSlabFarScale;
}

// Closest hit (kAnyHit = false) or first hit (kAnyHit = true). kBehind:
// the ray has tmin < 0, so entry distances may be negative, whose bits do
// not order as the sort's unsigned keys (simd::distance_key); such rays
// order three or more hit children by a float insertion sort instead.
template <int N, bool kAnyHit, bool kCount, bool kBehind>
inline Hit traverse_ray(const WideBvhView<N>& bvh, const Ray& ray, TraversalCounters* counters) {
    using namespace simd;
    Hit hit;
    if (bvh.node_count == 0) return hit;
    const BoxRay<N> box_ray = BoxRay<N>::make(ray, bvh.coord_scale);
    // Set up at the first leaf: rays that miss every box (background pixels)
    // never pay for the triangle test's divisions.
    PackRay tri_ray;
    bool tri_ray_ready = false;
    const float tmin = ray.tmin;
    float tmax = ray.tmax;
    const vfloat<N> tmin_v = set1<N>(tmin);
    float tmax_far = widen_tmax<kBehind>(tmax);
    vfloat<N> tmax_far_v = set1<N>(tmax_far);

    StackItem stack[kStackSize<N>];
    int size = 0;
    uint32_t ref = 0;  // the root is always an inner node
    for (;;) {
        // Descend, nearest child first, until a leaf is reached or nothing is hit.
        bool reached_leaf = true;
        while (!wide_is_leaf(ref)) {
            const WideNode<N>& node = bvh.nodes[ref];
            if constexpr (kCount) {
                ++counters->nodes_visited;
                ++counters->node_fetches;  // one wide node, all its boxes
            }
            vfloat<N> near_v;
            unsigned mask = box_hits(node, box_ray, tmin_v, tmax_far_v, near_v);
            if (mask == 0) {
                reached_leaf = false;
                break;
            }
            const unsigned hit_mask = mask;
            alignas(32) float near[N];
            store<N>(near, near_v);
            const int c0 = first_bit(mask);
            mask &= mask - 1;
            if (mask == 0) {
                ref = node.child[c0];
                continue;
            }
            const int c1 = first_bit(mask);
            mask &= mask - 1;
            if (mask == 0) {
                if (near[c1] < near[c0]) {
                    ref = node.child[c1];
                    stack[size++] = {node.child[c0], near[c0]};
                } else {
                    ref = node.child[c0];
                    stack[size++] = {node.child[c1], near[c1]};
                }
                if constexpr (kPrefetch) prefetch_ref(bvh, stack[size - 1].ref);
                continue;
            }
            if constexpr (kAnyHit) {
                // Any hit ends the search, wherever it is: no ordering.
                stack[size++] = {node.child[c1], near[c1]};
                for (; mask; mask &= mask - 1) {
                    const int c = first_bit(mask);
                    stack[size++] = {node.child[c], near[c]};
                }
                ref = node.child[c0];
                continue;
            }
            // Three or more: sort by entry distance, push all but the nearest far
            // to near (so the nearest waiting one is popped first), take the nearest.
            if constexpr (kBehind) {
                int order[N];
                int count = 0;
                for (unsigned m = hit_mask; m; m &= m - 1) {
                    const int c = first_bit(m);
                    int at = count++;
                    for (; at > 0 && near[order[at - 1]] > near[c]; --at) order[at] = order[at - 1];
                    order[at] = c;
                }
                for (int i = count - 1; i > 0; --i) {
                    stack[size++] = {node.child[order[i]], near[order[i]]};
                    if constexpr (kPrefetch) prefetch_ref(bvh, stack[size - 1].ref);
                }
                ref = node.child[order[0]];
                continue;
            }
            alignas(32) uint32_t keys[N];
            sort_distance_keys<N>(near_v, hit_mask, keys);
            for (int i = bit_count(hit_mask) - 1; i > 0; --i) {
                stack[size++] = {node.child[keys[i] & 7u], key_distance(keys[i])};
                if constexpr (kPrefetch) prefetch_ref(bvh, stack[size - 1].ref);
            }
            ref = node.child[keys[0] & 7u];
        }
        if (reached_leaf) {
            if (!tri_ray_ready) {
                tri_ray = PackRay::make(ray);
                tri_ray_ready = true;
            }
            const uint32_t first = wide_leaf_first_pack(ref);
            const uint32_t end = first + wide_leaf_pack_count(ref);
            for (uint32_t p = first; p < end; ++p) {
                const TrianglePack& pack = bvh.packs[p];
                if constexpr (kCount) counters->prims_tested += pack_reference_count(pack);
                alignas(16) float t[4], u[4], v[4];
                unsigned lanes = intersect_pack(tri_ray, pack, tmin, tmax, t, u, v);
                if (lanes == 0) continue;
                int best = first_bit(lanes);
                for (lanes &= lanes - 1; lanes; lanes &= lanes - 1) {
                    const int lane = first_bit(lanes);
                    if (t[lane] < t[best]) best = lane;
                }
                hit.t = t[best];
                hit.u = u[best];
                hit.v = v[best];
                hit.prim = pack.prim[best];
                if constexpr (kAnyHit) return hit;
                tmax = hit.t;  // later boxes and triangles must beat it
            }
            tmax_far = widen_tmax<kBehind>(tmax);
            tmax_far_v = set1<N>(tmax_far);
        }
        // Pop the next node the ray still reaches before the closest hit.
        for (;;) {
            if (size == 0) return hit;
            const StackItem item = stack[--size];
            if (item.dist <= tmax_far) {
                ref = item.ref;
                break;
            }
        }
    }
}

template <int N, bool kAnyHit, bool kCount>
inline Hit traverse(const WideBvhView<N>& bvh, const Ray& ray, TraversalCounters* counters) {
    if (ray.tmin < 0.0f) return traverse_ray<N, kAnyHit, kCount, true>(bvh, ray, counters);
    return traverse_ray<N, kAnyHit, kCount, false>(bvh, ray, counters);
}

}  // namespace wide_detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim indexes the scene's triangles.
template <int N>
inline Hit wide_bvh_intersect(const WideBvhView<N>& bvh, const Ray& ray) {
    return wide_detail::traverse<N, false, false>(bvh, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
template <int N>
inline bool wide_bvh_occluded(const WideBvhView<N>& bvh, const Ray& ray) {
    return wide_detail::traverse<N, true, false>(bvh, ray, nullptr).found();
}

// Counting variants (steps = wide nodes visited, prim tests = triangle references tested).
template <int N>
inline Hit wide_bvh_intersect_counted(const WideBvhView<N>& bvh, const Ray& ray, TraversalCounters& counters) {
    return wide_detail::traverse<N, false, true>(bvh, ray, &counters);
}
template <int N>
inline bool wide_bvh_occluded_counted(const WideBvhView<N>& bvh, const Ray& ray, TraversalCounters& counters) {
    return wide_detail::traverse<N, true, true>(bvh, ray, &counters).found();
}

}  // namespace rf
