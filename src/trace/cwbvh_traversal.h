// Closest-hit and any-hit traversal of the compressed 8-wide BVH
// (accel/bvh/layout/cwbvh_layout.h) after Algorithm 1 of Ylitie, Karras and
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
// more, and then tests the node's leaf triangles.
//
// Triangle postponement (the paper's section 5 and Algorithm 1): on the
// GPU, a node's triangles are tested one per loop trip by the lanes that
// have some, so a warp where only a few lanes have triangles left runs
// nearly empty. When, before a triangle, fewer than kCwbvhPostponeRatio
// (20 %, the paper's threshold) of the lanes that started the iteration are
// still in the triangle loop, the lane pushes its remaining triangle group
// (base triangle index, bits 0..23 the triangles left, bits 24..31 zero) and
// goes on with node traversal; the group is tested when popped. A popped
// entry is therefore a node group (bits 24..31 nonzero) or a triangle group,
// and the loop dispatches on that. The decision is a policy (template
// parameter, like the counters): the default reads __activemask() on the
// device and never postpones on the host, where one ray is its own warp;
// tests pass policies that postpone always or at random. The hit distance
// does not depend on the policy (postponing only reorders the triangle
// tests, each against the current tmax; among triangles at exactly the same
// distance the one reported may change), nor does the work on a ray that
// hits nothing.
// Two deviations from Algorithm 1, neither changes results: a popped
// triangle group is not postponed again, and a node's triangles are only
// postponed while the node has hit inner children to go on with; in both
// other cases the next step would pop the group straight back, so the push
// would be pure overhead (and for a popped group with an always-postponing
// policy, an endless loop).
// Stack bound: entries, bottom to top, are ordered by wide level, with at
// most one node group (siblings left at that level) and one triangle group
// (of a node at that level that has inner children) per level. In a wide
// tree of depth D <= kCwbvhMaxDepth that is at most (D - 1) node groups
// (levels 2..D) and (D - 1) triangle groups (levels 1..D - 1), i.e. at most
// 2 * kCwbvhStackSize entries: kCwbvhTraversalStackSize.
//
// Boxes: the dequantised child box (cwbvh_child_box, the one the builder
// checked to contain the exact box) goes through the robust slab test of
// trace/bvh_traversal.h (Ize 2013), where the paper uses a cheaper per-node
// transformed ray (that is the cwbvh-fma variant, trace/cwbvh_fma_traversal.h,
// which shares this file's loop: detail::cwbvh_resume, resumable for
// persistent threads, over a node visit found by overload); triangles through
// the scalar watertight test on the original vertices, so t, u, v equal the
// canonical traversal's.
#pragma once

#include <cstdint>
#include <cstring>

#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "core/assert.h"
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

// Entries of the traversal stack: one node group and one triangle group per
// wide level below the root (see the top of this file).
inline constexpr int kCwbvhTraversalStackSize = 2 * kCwbvhStackSize;

// Postpone a node's remaining triangles when fewer than this fraction of the
// lanes active at the start of the iteration are still testing triangles
// (Ylitie, Karras and Laine 2017, section 5: 20 %).
inline constexpr float kCwbvhPostponeRatio = 0.2f;

namespace detail {

using rf::cwbvh_popc;

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
// (8-byte aligned: one 64-bit stack load or store.)
struct alignas(8) CwbvhGroup {
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

// What visiting a node hands the loop: the child hit mask (as above), the
// node's child and triangle bases and its imask.
struct CwbvhNodeHits {
    uint32_t hits;
    uint32_t base_child;
    uint32_t base_triangle;
    uint32_t imask;
};

// The node visit of this traversal: one copy of the whole 80-byte node, its
// child boxes through the robust slab test. (The cwbvh-fma variant,
// trace/cwbvh_fma_traversal.h, overloads this on its own per-ray data.)
template <class Counters>
RF_HDI CwbvhNodeHits cwbvh_visit_node(const CwbvhView& bvh, uint32_t index, const SlabRay& slab, uint32_t oct_inv,
                                      float tmin, float tmax, Counters* counters) {
    const CwbvhNode node = bvh.nodes[index];
    if constexpr (Counters::kCount) counters->node();
    return {cwbvh_child_hits(node, slab, tmin, tmax, oct_inv, counters), node.base_index_child,
            node.base_index_triangle, node.imask};
}

// The traversal stack as a plain array (host, and device threads without
// shared memory set aside for it).
struct CwbvhLocalStack {
    CwbvhGroup entries[kCwbvhTraversalStackSize];
    RF_HDI void store(int i, CwbvhGroup g) { entries[i] = g; }
    RF_HDI CwbvhGroup load(int i) const { return entries[i]; }
};

// A ray that never steps aside (see cwbvh_resume).
struct CwbvhNeverYield {
    RF_HDI static bool yield_for_refill() { return false; }
};

// Counter adapters: none, TraversalCounters (nodes_visited = box tests, as
// in the other traversals, node_fetches = nodes) or CwbvhCounters.
struct CwbvhNoCount {
    static constexpr bool kCount = false;
    RF_HDI void node() {}
    RF_HDI void box() {}
    RF_HDI void prim() {}
};
struct CwbvhCountBoxes {
    static constexpr bool kCount = true;
    TraversalCounters* c;
    RF_HDI void node() { ++c->node_fetches; }
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

}  // namespace detail

// Postponement policies. The traversal calls begin_iteration() at the start
// of every main-loop iteration, postpone() before each triangle it may
// postpone (true: push the triangles left and go on with the nodes), and
// pushed(size) after every push with the new stack size (instrumentation).
// The default, the paper's heuristic: on the device, postpone when fewer
// than kCwbvhPostponeRatio of the iteration's lanes are in the triangle
// loop; on the host, never.
struct CwbvhPostponeOnFewActiveLanes {
    uint32_t lanes = 0;  // active lanes at the start of the iteration (device)
    RF_HDI void begin_iteration() {
#if defined(__CUDA_ARCH__)
        lanes = detail::cwbvh_popc(__activemask());
#endif
    }
    RF_HDI bool postpone() {
#if defined(__CUDA_ARCH__)
        return float(detail::cwbvh_popc(__activemask())) < float(lanes) * kCwbvhPostponeRatio;
#else
        return false;
#endif
    }
    RF_HDI void pushed(int) {}
};

// Everything one ray's traversal needs to stop and resume (the stack's
// entries live in the caller's Stack, its size here): `box` is the per-ray
// data of the variant's box test, tri_ray the watertight test's, `group` the
// node or triangle group to go on with.
template <class BoxRay>
struct CwbvhRayState {
    BoxRay box;
    WatertightRay tri_ray;
    float tmin;
    float tmax;
    uint32_t oct_inv;  // 7 - octant: the XOR that orders the inner children
    detail::CwbvhGroup group;
    int stack_size;
    Hit hit;
};

// The ray's state before its first step; `box` must be set by the caller.
// octant: the direction's sign bits (bit a set = negative along axis a).
template <class BoxRay>
RF_HDI void cwbvh_begin(const CwbvhView& bvh, const Ray& ray, uint32_t octant, CwbvhRayState<BoxRay>& s) {
    s.tri_ray = WatertightRay::make(ray);
    s.tmin = ray.tmin;
    s.tmax = ray.tmax;
    s.oct_inv = 7u - octant;
    // The root as the only child (slot 0, inner) of a virtual parent at base
    // 0; an empty BVH starts with nothing to do.
    s.group = {0u, bvh.node_count == 0 ? 0u : (1u << (24u + s.oct_inv)) | 1u};
    s.stack_size = 0;
    s.hit = Hit{};
}

namespace detail {

// Algorithm 1's loop, shared by the variants (the node visit is found by
// overload on BoxRay): runs until the ray is done (returns true; s.hit is
// the closest hit, or the first for kAnyHit) or, between two iterations
// (no triangle group in flight), until yield.yield_for_refill() asks it to
// step aside (returns false; call again to resume).
template <bool kAnyHit, class BoxRay, class Stack, class Counters, class Postpone, class Yield>
RF_HDI bool cwbvh_resume(const CwbvhView& bvh, CwbvhRayState<BoxRay>& s, Stack& stack, Counters* counters,
                         Postpone* postpone, Yield& yield) {
    // Working copies (registers); the state is written back on leaving.
    const BoxRay box = s.box;
    const WatertightRay tri_ray = s.tri_ray;
    const float tmin = s.tmin;
    const uint32_t oct_inv = s.oct_inv;
    float tmax = s.tmax;
    CwbvhGroup group = s.group;
    int stack_size = s.stack_size;
    Hit hit = s.hit;
    for (;;) {
        postpone->begin_iteration();
        CwbvhGroup triangles;
        bool may_postpone;
        if (group.hits & kCwbvhNodeBits) {
            // A node group: its nearest remaining child in octant order.
            const int bit = cwbvh_highest_bit(group.hits & kCwbvhNodeBits);
            group.hits &= ~(1u << bit);
            const uint32_t slot = static_cast<uint32_t>(bit - 24) ^ oct_inv;
            const uint32_t below = (group.hits & 0xFFu) & ((1u << slot) - 1u);
            const uint32_t index = group.base + cwbvh_popc(below);
            if (group.hits & kCwbvhNodeBits) {
                RF_ASSERT(stack_size < kCwbvhTraversalStackSize, "CWBVH traversal stack overflow");
                stack.store(stack_size++, group);
                postpone->pushed(stack_size);
            }

            const CwbvhNodeHits node = cwbvh_visit_node(bvh, index, box, oct_inv, tmin, tmax, counters);
            group = {node.base_child, (node.hits & kCwbvhNodeBits) | node.imask};
            triangles = {node.base_triangle, node.hits & kCwbvhTriangleBits};
            may_postpone = (group.hits & kCwbvhNodeBits) != 0;
        } else {
            // A postponed triangle group, tested now.
            triangles = group;
            group.hits = 0;
            may_postpone = false;
        }

        // The hit leaves' triangles, one by one.
        while (triangles.hits != 0) {
            if (may_postpone && postpone->postpone()) {
                RF_ASSERT(stack_size < kCwbvhTraversalStackSize, "CWBVH traversal stack overflow");
                stack.store(stack_size++, triangles);
                postpone->pushed(stack_size);
                break;
            }
            const int k = cwbvh_lowest_bit(triangles.hits);
            triangles.hits &= triangles.hits - 1u;
            const CwbvhTriangle& t = bvh.triangles[triangles.base + static_cast<uint32_t>(k)];
            const Triangle tri{Vec3f(t.v0.x, t.v0.y, t.v0.z), Vec3f(t.v1.x, t.v1.y, t.v1.z),
                               Vec3f(t.v2.x, t.v2.y, t.v2.z)};
            if constexpr (Counters::kCount) counters->prim();
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, tri, tmin, tmax, candidate)) {
                hit.t = candidate.t;
                hit.u = candidate.u;
                hit.v = candidate.v;
                hit.prim = float_to_bits(t.v0.w);
                if constexpr (kAnyHit) {  // any hit: the first ends it
                    s.hit = hit;
                    s.group = {0u, 0u};
                    s.stack_size = 0;
                    return true;
                }
                tmax = candidate.t;  // later boxes and triangles must beat it
            }
        }

        const bool done = (group.hits & kCwbvhNodeBits) == 0 && stack_size == 0;
        if (!done && (group.hits & kCwbvhNodeBits) == 0) group = stack.load(--stack_size);  // node or triangle group
        if (done || yield.yield_for_refill()) {
            s.tmax = tmax;
            s.group = done ? CwbvhGroup{0u, 0u} : group;
            s.stack_size = stack_size;
            s.hit = hit;
            return done;
        }
    }
}

// One ray from start to end with the plain stack and no yields.
template <bool kAnyHit, class Counters, class Postpone>
RF_HDI Hit cwbvh_traverse(const CwbvhView& bvh, const Ray& ray, Counters* counters, Postpone* postpone) {
    if (bvh.node_count == 0) return Hit{};
    CwbvhRayState<SlabRay> s;
    s.box = SlabRay::make(ray);
    // Sign bits of the direction (bit set = negative, -0 included via 1 / dir).
    const uint32_t octant = (s.box.neg_x ? 1u : 0u) | (s.box.neg_y ? 2u : 0u) | (s.box.neg_z ? 4u : 0u);
    cwbvh_begin(bvh, ray, octant, s);
    CwbvhLocalStack stack;
    CwbvhNeverYield never;
    cwbvh_resume<kAnyHit>(bvh, s, stack, counters, postpone, never);
    return s.hit;
}

}  // namespace detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim is the triangle index the
// layout was built with.
RF_HDI Hit cwbvh_intersect(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<false>(bvh, ray, &none, &postpone);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
RF_HDI bool cwbvh_occluded(const CwbvhView& bvh, const Ray& ray) {
    detail::CwbvhNoCount none;
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<true>(bvh, ray, &none, &postpone).found();
}

// Counting variants (counters are accumulated). With TraversalCounters,
// nodes_visited counts child box tests, as the other traversals do; with
// CwbvhCounters, node fetches and box tests are counted separately.
RF_HDI Hit cwbvh_intersect_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountBoxes count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<false>(bvh, ray, &count, &postpone);
}
RF_HDI bool cwbvh_occluded_counted(const CwbvhView& bvh, const Ray& ray, TraversalCounters& counters) {
    detail::CwbvhCountBoxes count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<true>(bvh, ray, &count, &postpone).found();
}
RF_HDI Hit cwbvh_intersect_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters) {
    detail::CwbvhCountAll count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<false>(bvh, ray, &count, &postpone);
}
RF_HDI bool cwbvh_occluded_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters) {
    detail::CwbvhCountAll count{&counters};
    CwbvhPostponeOnFewActiveLanes postpone;
    return detail::cwbvh_traverse<true>(bvh, ray, &count, &postpone).found();
}

// The same with a caller's postponement policy (see CwbvhPostponeOnFewActiveLanes).
template <class Postpone>
RF_HDI Hit cwbvh_intersect(const CwbvhView& bvh, const Ray& ray, Postpone& postpone) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_traverse<false>(bvh, ray, &none, &postpone);
}
template <class Postpone>
RF_HDI bool cwbvh_occluded(const CwbvhView& bvh, const Ray& ray, Postpone& postpone) {
    detail::CwbvhNoCount none;
    return detail::cwbvh_traverse<true>(bvh, ray, &none, &postpone).found();
}
template <class Postpone>
RF_HDI Hit cwbvh_intersect_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters,
                                   Postpone& postpone) {
    detail::CwbvhCountAll count{&counters};
    return detail::cwbvh_traverse<false>(bvh, ray, &count, &postpone);
}
template <class Postpone>
RF_HDI bool cwbvh_occluded_counted(const CwbvhView& bvh, const Ray& ray, CwbvhCounters& counters,
                                   Postpone& postpone) {
    detail::CwbvhCountAll count{&counters};
    return detail::cwbvh_traverse<true>(bvh, ray, &count, &postpone).found();
}

}  // namespace rf
