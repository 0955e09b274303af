// Closest-hit and any-hit traversal of the compressed 8-wide BVH
// (accel/bvh/wide/cwbvh_layout.h) after Algorithm 1 of Ylitie, Karras and
// Laine 2017, "Efficient Incoherent Ray Traversal on GPUs Through Compressed
// Wide BVHs", written once for the host and the CUDA backend: plain pointers
// in, no std containers, no exceptions.
//
// The traversal state is the paper's: a node group (the base index of a
// node's inner children plus a 32-bit word whose bits 24..31 are the hit
// children not yet visited and whose bits 0..7 are the node's imask) and a
// triangle group (base triangle index plus a 24-bit hit mask). A node's hit
// children set the bits (meta >> 5) << (meta & 31); for inner children the
// low meta bits 24 + slot are XORed with the inverse ray octant, so taking
// the highest set bit visits the children in the octant order the builder
// arranged (nearly front to back) without sorting. The child's index is the
// group base plus the number of inner slots below it (popc of the imask).
// Each iteration visits one node, pushes the rest of its group when it has
// more, and then tests the node's leaf triangles. The paper's postponing of
// triangle groups while few SIMT lanes are active is a GPU scheduling
// heuristic that does not change results; it is left out, so the stack only
// ever holds node groups (at most one per wide level below the root, which
// build_cwbvh bounds by kCwbvhStackSize).
//
// Boxes: the dequantised child box (cwbvh_child_box, the one the builder
// checked to contain the exact box) goes through the robust slab test of
// trace/bvh_traversal.h (Ize 2013), where the paper uses a cheaper per-node
// transformed ray; triangles through the scalar watertight test on the
// original vertices, so t, u, v equal the canonical traversal's.
#pragma once

#include <cstdint>
#include <cstring>

#include "accel/bvh/wide/cwbvh_layout.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/bvh_traversal.h"
#include "trace/triangle_intersect.h"

namespace rf {

// Work done by one CWBVH traversal (the counted variants add to it).
struct CwbvhCounters {
    uint32_t nodes_visited = 0;  // 80-byte nodes fetched
    uint32_t boxes_tested = 0;   // child boxes tested
    uint32_t prims_tested = 0;   // triangle tests
};

namespace detail {

RF_HDI uint32_t cwbvh_popc(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return static_cast<uint32_t>(__popc(x));
#else
    return static_cast<uint32_t>(__builtin_popcount(x));
#endif
}

// Index of the highest / lowest set bit; x != 0.
RF_HDI int cwbvh_highest_bit(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return 31 - __clz(x);
#else
    return 31 - __builtin_clz(x);
#endif
}
RF_HDI int cwbvh_lowest_bit(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return __ffs(x) - 1;
#else
    return __builtin_ctz(x);
#endif
}

// base: first inner child (node group) of the node the bits came from;
// hits: bits 24..31 children left to visit, bits 0..7 that node's imask.
struct CwbvhGroup {
    uint32_t base;
    uint32_t hits;
};

inline constexpr uint32_t kCwbvhNodeBits = 0xFF000000u;
inline constexpr uint32_t kCwbvhTriangleBits = 0x00FFFFFFu;

// Tests the node's child boxes; returns the hit mask (inner children at
// 24 + (slot ^ oct_inv), leaf triangles at their offsets).
template <class Counters>
RF_HDI uint32_t cwbvh_child_hits(const CwbvhNode& node, const SlabRay& slab, float tmin, float tmax,
                                 uint32_t oct_inv, Counters* counters) {
    uint32_t hits = 0;
    for (int slot = 0; slot < kCwbvhWidth; ++slot) {
        const uint32_t meta = node.meta[slot];
        if (meta == kCwbvhEmptyMeta) continue;
        if constexpr (Counters::kCount) counters->box();
        float entry;
        if (!slab_test(slab, cwbvh_child_box(node, slot), tmin, tmax, entry)) continue;
        // Inner: meta & 31 is 24 + slot (< 32), so the XOR only permutes the slot bits.
        const uint32_t bit_index = cwbvh_meta_is_inner(static_cast<uint8_t>(meta)) ? (meta ^ oct_inv) & 31u
                                                                                   : meta & 31u;
        hits |= (meta >> 5) << bit_index;
    }
    return hits;
}

// Counter adapters: none, TraversalCounters (nodes_visited = box tests, as
// in the other traversals) or CwbvhCounters.
struct CwbvhNoCount {
    static constexpr bool kCount = false;
    RF_HDI void node() {}
    RF_HDI void box() {}
    RF_HDI void prim() {}
};
struct CwbvhCountBoxes {
    static constexpr bool kCount = true;
    TraversalCounters* c;
    RF_HDI void node() {}
    RF_HDI void box() { ++c->nodes_visited; }
    RF_HDI void prim() { ++c->prims_tested; }
};
struct CwbvhCountAll {
    static constexpr bool kCount = true;
    CwbvhCounters* c;
    RF_HDI void node() { ++c->nodes_visited; }
    RF_HDI void box() { ++c->boxes_tested; }
    RF_HDI void prim() { ++c->prims_tested; }
};

// Shared loop: closest hit (kAnyHit = false) or first hit (kAnyHit = true).
template <bool kAnyHit, class Counters>
RF_HDI Hit cwbvh_traverse(const CwbvhView& bvh, const Ray& ray, Counters* counters) {
    Hit hit;
    if (bvh.node_count == 0) return hit;
    const SlabRay slab = SlabRay::make(ray);
    const WatertightRay tri_ray = WatertightRay::make(ray);
    const float tmin = ray.tmin;
    float tmax = ray.tmax;
    // Sign bits of the direction (bit set = negative, -0 included via 1 / dir).
    const uint32_t octant = (slab.neg_x ? 1u : 0u) | (slab.neg_y ? 2u : 0u) | (slab.neg_z ? 4u : 0u);
    const uint32_t oct_inv = 7u - octant;

    CwbvhGroup stack[kCwbvhStackSize];
    int stack_size = 0;
    // The root as the only child (slot 0, inner) of a virtual parent at base 0.
    CwbvhGroup group{0u, (1u << (24u + oct_inv)) | 1u};
    for (;;) {
        // Nearest remaining child of the group in octant order.
        const int bit = cwbvh_highest_bit(group.hits & kCwbvhNodeBits);
        group.hits &= ~(1u << bit);
        const uint32_t slot = static_cast<uint32_t>(bit - 24) ^ oct_inv;
        const uint32_t below = (group.hits & 0xFFu) & ((1u << slot) - 1u);
        const uint32_t index = group.base + cwbvh_popc(below);
        if (group.hits & kCwbvhNodeBits) stack[stack_size++] = group;

        // One copy of the whole 80-byte node: five 16-byte loads on the GPU
        // instead of a byte load per field.
        const CwbvhNode node = bvh.nodes[index];
        if constexpr (Counters::kCount) counters->node();
        const uint32_t hits = cwbvh_child_hits(node, slab, tmin, tmax, oct_inv, counters);
        group = {node.base_index_child, (hits & kCwbvhNodeBits) | node.imask};

        // The node's hit leaves, triangle by triangle.
        uint32_t triangle_hits = hits & kCwbvhTriangleBits;
        while (triangle_hits != 0) {
            const int k = cwbvh_lowest_bit(triangle_hits);
            triangle_hits &= triangle_hits - 1u;
            const CwbvhTriangle& t = bvh.triangles[node.base_index_triangle + static_cast<uint32_t>(k)];
            const Triangle tri{Vec3f(t.v0.x, t.v0.y, t.v0.z), Vec3f(t.v1.x, t.v1.y, t.v1.z),
                               Vec3f(t.v2.x, t.v2.y, t.v2.z)};
            if constexpr (Counters::kCount) counters->prim();
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, tri, tmin, tmax, candidate)) {
                hit.t = candidate.t;
                hit.u = candidate.u;
                hit.v = candidate.v;
                hit.prim = float_to_bits(t.v0.w);
                if constexpr (kAnyHit) return hit;  // any hit: the first ends it
                tmax = candidate.t;                 // later boxes and triangles must beat it
            }
        }

        if ((group.hits & kCwbvhNodeBits) == 0) {
            if (stack_size == 0) return hit;
            group = stack[--stack_size];
        }
    }
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim is the triangle index the
// layout was built with.
RF_HDI Hit cwbvh_intersect(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_traverse<false>(bvh, ray, &none);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool cwbvh_occluded(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_traverse<true>(bvh, ray, &none).found();
}

// Counting variants (counters are accumulated). With TraversalCounters,
// nodes_visited counts child box tests, as the other traversals do; with
// CwbvhCounters, node fetches and box tests are counted separately.
RF_HDI Hit cwbvh_intersect_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountBoxes count{&counters};
    return detail::cwbvh_traverse<false>(bvh, ray, &count);
}
RF_HDI bool cwbvh_occluded_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountBoxes count{&counters};
    return detail::cwbvh_traverse<true>(bvh, ray, &count).found();
}
RF_HDI Hit cwbvh_intersect_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters) {
    detail::CwbvhCountAll count{&counters};
    return detail::cwbvh_traverse<false>(bvh, ray, &count);
}
RF_HDI bool cwbvh_occluded_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters) {
    detail::CwbvhCountAll count{&counters};
    return detail::cwbvh_traverse<true>(bvh, ray, &count).found();
}

}  // namespace rf
