// The closest-point query over the 8-wide BVH (accel/bvh/layout/wide_bvh.h:
// child boxes as structure-of-arrays, leaves of 4-triangle packs), the one
// MeshQueries answers batches with on the CPU; closest_point.h's binary
// query is its reference (and the form a device kernel would take).
//
// The point-query counterpart of the wide ray traversal (Wald, Benthin and
// Boulos 2008): one SIMD pass computes the squared distances from the query
// to the eight child boxes; the children within the best squared distance
// so far are sorted by it (simd::sort_distance_keys), the nearest visited
// next and the others pushed, farthest first, with their distances, and
// skipped when popped once a closer triangle is known. A node is entered
// while its distance is <= the best (keys round distances down, which only
// enters more nodes), so equally close triangles are all tested and ties go
// to the smallest prim, as in the binary query.
//
// Leaves: Ericson 5.1.5 (closest_point.h) on a pack's four triangles at
// once. Every region's test and candidate is computed in every lane and the
// first region in Ericson's order selected by masks; the lanes do the
// scalar operations in the same order (the project compiles with
// -ffp-contract=off), so their squared distances equal
// closest_point_on_triangle's bit for bit. A lane that improves the best is
// computed again by the scalar code for its point and barycentrics. Lanes
// the packed test cannot answer go to the scalar code: zero-area triangles
// (NaN in the packs) and slivers whose face denominator rounds to zero.
#pragma once

#include <bit>
#include <cstdint>

#include "accel/bvh/layout/wide_bvh.h"
#include "accel/query/closest_point.h"
#include "core/simd.h"

namespace rf::query {

struct WidePointView {
    const WideNode<8>* nodes = nullptr;  // null: the empty mesh
    const TrianglePack* packs = nullptr;
    QueryView slots;                     // the scalar code's triangles (slots.slots) ...
    const uint32_t* slot_of_prim = nullptr;  // ... found by prim
};

namespace wide_point {

using simd::vfloat;
using simd::vmask;

#if defined(RF_SIMD_SSE)
// SSE2 only (and/andnot/or, the masks are whole lanes): the library is
// also built without -march=native (the fuzzers, RAYFORGE_NATIVE=OFF).
RF_SIMD_INLINE vfloat<4> select(vmask<4> m, vfloat<4> a, vfloat<4> b) {
    return {_mm_or_ps(_mm_and_ps(m.v, a.v), _mm_andnot_ps(m.v, b.v))};
}
RF_SIMD_INLINE vmask<4> and_not(vmask<4> a, vmask<4> b) { return {_mm_andnot_ps(b.v, a.v)}; }
RF_SIMD_INLINE vmask<4> is_nan(vfloat<4> a) { return {_mm_cmpunord_ps(a.v, a.v)}; }
#else
RF_SIMD_INLINE vfloat<4> select(vmask<4> m, vfloat<4> a, vfloat<4> b) {
    vfloat<4> r;
    for (int i = 0; i < 4; ++i) r.v[i] = (m.bits >> i) & 1u ? a.v[i] : b.v[i];
    return r;
}
RF_SIMD_INLINE vmask<4> and_not(vmask<4> a, vmask<4> b) { return {a.bits & ~b.bits}; }
RF_SIMD_INLINE vmask<4> is_nan(vfloat<4> a) {
    vmask<4> m{0};
    for (int i = 0; i < 4; ++i) m.bits |= a.v[i] != a.v[i] ? 1u << i : 0u;
    return m;
}
#endif

struct V3 {
    vfloat<4> x, y, z;
};
RF_SIMD_INLINE V3 sub3(V3 a, V3 b) { return {simd::sub(a.x, b.x), simd::sub(a.y, b.y), simd::sub(a.z, b.z)}; }
RF_SIMD_INLINE vfloat<4> dot3(V3 a, V3 b) {  // (x + y) + z, as rf::dot
    using namespace simd;
    return add(add(mul(a.x, b.x), mul(a.y, b.y)), mul(a.z, b.z));
}
RF_SIMD_INLINE V3 select3(vmask<4> m, V3 a, V3 b) { return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)}; }
RF_SIMD_INLINE vfloat<4> safe_ratio(vfloat<4> num, vfloat<4> den) {
    const vfloat<4> zero = simd::set1<4>(0.0f);
    return select(simd::cmp_gt(den, zero), simd::div(num, den), zero);
}

// Squared distances from p to the pack's four triangles, equal to
// length_squared(closest_point_on_triangle(p, t).point - p) in the lanes
// not set in `scalar_lanes` (zero-area and empty lanes, face-region slivers).
RF_SIMD_INLINE vfloat<4> pack_distances(const TrianglePack& pack, const V3& p, unsigned& scalar_lanes) {
    using namespace simd;
    const vfloat<4> zero = set1<4>(0.0f);
    const V3 a{load<4>(pack.v[0][0]), load<4>(pack.v[0][1]), load<4>(pack.v[0][2])};
    const V3 b{load<4>(pack.v[1][0]), load<4>(pack.v[1][1]), load<4>(pack.v[1][2])};
    const V3 c{load<4>(pack.v[2][0]), load<4>(pack.v[2][1]), load<4>(pack.v[2][2])};
    const V3 ab = sub3(b, a), ac = sub3(c, a);
    const V3 ap = sub3(p, a), bp = sub3(p, b), cp = sub3(p, c);
    const vfloat<4> d1 = dot3(ab, ap), d2 = dot3(ac, ap);
    const vfloat<4> d3 = dot3(ab, bp), d4 = dot3(ac, bp);
    const vfloat<4> d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    const vfloat<4> vc = sub(mul(d1, d4), mul(d3, d2));
    const vfloat<4> vb = sub(mul(d5, d2), mul(d1, d6));
    const vfloat<4> va = sub(mul(d3, d6), mul(d5, d4));
    const vfloat<4> e43 = sub(d4, d3), e56 = sub(d5, d6);

    const vmask<4> in_a = cmp_le(d1, zero) & cmp_le(d2, zero);
    const vmask<4> in_b = cmp_ge(d3, zero) & cmp_le(d4, d3);
    const vmask<4> in_ab = cmp_le(vc, zero) & cmp_ge(d1, zero) & cmp_le(d3, zero);
    const vmask<4> in_c = cmp_ge(d6, zero) & cmp_le(d5, d6);
    const vmask<4> in_ac = cmp_le(vb, zero) & cmp_ge(d2, zero) & cmp_le(d6, zero);
    const vmask<4> in_bc = cmp_le(va, zero) & cmp_ge(e43, zero) & cmp_ge(e56, zero);
    const vmask<4> not_face = in_a | in_b | in_ab | in_c | in_ac | in_bc;

    // The point is (o + d * s) + ac * s2: the face's (v0 + ab v) + ac w, an
    // edge's start + edge * s (s2 = 0) or a vertex (s = s2 = 0). Regions in
    // reverse order of Ericson's tests, so the first test that holds wins.
    const vfloat<4> sum = add(add(va, vb), vc);
    const vfloat<4> inv = div(set1<4>(1.0f), sum);
    V3 o = a, d = ab;
    vfloat<4> s = mul(vb, inv), s2 = mul(vc, inv);
    s = select(in_bc, safe_ratio(e43, add(e43, e56)), s);
    o = select3(in_bc, b, o);
    d = select3(in_bc, sub3(c, b), d);
    s = select(in_ac, safe_ratio(d2, sub(d2, d6)), s);
    o = select3(in_ac, a, o);
    d = select3(in_ac, ac, d);
    s = select(in_c, zero, s);
    o = select3(in_c, c, o);
    s = select(in_ab, safe_ratio(d1, sub(d1, d3)), s);
    o = select3(in_ab, a, o);
    d = select3(in_ab, ab, d);
    s = select(in_b, zero, s);
    o = select3(in_b, b, o);
    s = select(in_a, zero, s);
    o = select3(in_a, a, o);
    s2 = select(not_face, zero, s2);

    const V3 q{add(add(o.x, mul(d.x, s)), mul(ac.x, s2)), add(add(o.y, mul(d.y, s)), mul(ac.y, s2)),
               add(add(o.z, mul(d.z, s)), mul(ac.z, s2))};
    const V3 diff = sub3(q, p);
    scalar_lanes = bits(and_not(cmp_le(sum, zero) | is_nan(sum), not_face));
    return dot3(diff, diff);
}

}  // namespace wide_point

// The closest point of the view's triangles to p (p finite; prim ==
// kInvalidId for the empty mesh), seeded as closest_point_query is.
inline PointQueryResult wide_closest_point_query(const WidePointView& view, Vec3f p, uint32_t seed_slot = kInvalidId) {
    using namespace simd;
    using wide_point::V3;
    PointQueryResult best;
    if (view.nodes == nullptr) return best;
    if (seed_slot != kInvalidId) consider_slot(view.slots, p, seed_slot, best);
    struct Entry {
        uint32_t ref;
        float distance_squared;
    };
    Entry stack[8 * kBvhMaxDepth];  // at most seven pushed per level of the wide tree
    int size = 0;
    const vfloat<8> px = set1<8>(p.x), py = set1<8>(p.y), pz = set1<8>(p.z), zero = set1<8>(0.0f);
    const V3 p4{set1<4>(p.x), set1<4>(p.y), set1<4>(p.z)};
    uint32_t ref = 0;  // the root, an inner node
    for (;;) {
        if (!wide_is_leaf(ref)) {
            const WideNode<8>& node = view.nodes[ref];
            const vfloat<8> lox = load<8>(node.bounds[0]), hix = load<8>(node.bounds[1]);
            const vfloat<8> loy = load<8>(node.bounds[2]), hiy = load<8>(node.bounds[3]);
            const vfloat<8> loz = load<8>(node.bounds[4]), hiz = load<8>(node.bounds[5]);
            const vfloat<8> dx = max(max(sub(lox, px), sub(px, hix)), zero);
            const vfloat<8> dy = max(max(sub(loy, py), sub(py, hiy)), zero);
            const vfloat<8> dz = max(max(sub(loz, pz), sub(pz, hiz)), zero);
            const vfloat<8> d2 = add(add(mul(dx, dx), mul(dy, dy)), mul(dz, dz));
            // Empty slots (lo > hi) are never entered, even before any triangle is known.
            const unsigned mask = bits(cmp_le(d2, set1<8>(best.distance_squared)) & cmp_le(lox, hix));
            if (mask != 0) {
                if ((mask & (mask - 1u)) == 0) {
                    ref = node.child[std::countr_zero(mask)];
                    continue;
                }
                alignas(32) uint32_t keys[8];
                sort_distance_keys<8>(d2, mask, keys);
                const int count = std::popcount(mask);
                RF_ASSERT(size + count - 1 <= int(sizeof(stack) / sizeof(stack[0])), "a wide BVH deeper than kBvhMaxDepth");
                for (int k = count - 1; k >= 1; --k) stack[size++] = {node.child[keys[k] & 7u], key_distance(keys[k])};
                ref = node.child[keys[0] & 7u];
                continue;
            }
        } else {
            const uint32_t first = wide_leaf_first_pack(ref), end = first + wide_leaf_pack_count(ref);
            for (uint32_t k = first; k < end; ++k) {
                const TrianglePack& pack = view.packs[k];
                unsigned scalar_lanes = 0;
                alignas(16) float d[4];
                store<4>(d, wide_point::pack_distances(pack, p4, scalar_lanes));
                for (int lane = 0; lane < kTrianglePackWidth; ++lane) {
                    const uint32_t prim = pack.prim[lane];
                    if (prim == kInvalidId) continue;
                    const bool scalar = (scalar_lanes >> lane) & 1u;
                    // Bit-equal to the scalar distance: only a lane that may win is computed again in full.
                    if (scalar || d[lane] < best.distance_squared ||
                        (d[lane] == best.distance_squared && prim < best.prim)) {
                        consider_slot(view.slots, p, view.slot_of_prim[prim], best);
                    }
                }
            }
        }
        for (;;) {
            if (size == 0) return best;
            const Entry e = stack[--size];
            if (e.distance_squared <= best.distance_squared) {
                ref = e.ref;
                break;
            }
        }
    }
}

}  // namespace rf::query
