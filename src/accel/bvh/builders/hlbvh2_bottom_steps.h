// The per-node steps of HLBVH2's bottom levels (Garanzha 2014, dissertation
// ch. 5, "BVH construction with binary search and work queues"; Garanzha,
// Pantaleoni and McAllister, HPG 2011), written once for both backends: the
// CPU builder (hlbvh2.cpp) recurses with split_position(); the CUDA builder
// (backend/cuda/hlbvh2_build.cu) builds every cluster's bottom tree in ONE
// launch, one thread per split position, by the radix-tree rule of Karras
// 2012 ("Maximizing Parallelism in the Construction of BVHs, Octrees, and
// k-d Trees", HPG 2012, sec. 3-4: a node is found from its split, with no
// top-down order), then boxes them in one bottom-up launch with arrival
// counters (Karras sec. 4).
//
//  - split_position(): a node over sorted range [a, b) of 30-bit codes
//    splits where the highest bit in which codes[a] and codes[b-1] differ
//    turns from 0 to 1 (binary search for the first 1: the codes share every
//    higher bit, so that bit is 0s then 1s); all codes equal: halve by position.
//    The inner node is numbered mid - 1: each split position occurs once in
//    the whole forest, so node indices are fixed by the input.
//  - node_of_split(): the range of inner node i, the one splitting at
//    position i + 1, found from i alone. Codes i and i + 1 in one cluster
//    differ first in some bit h: the node is every code sharing the bits
//    above h with them (a maximal prefix range: HLBVH2's split of a range at
//    its highest differing bit is the binary radix tree's, so its ranges are
//    the radix tree's). Equal codes: i + 1 lies in a run of equal codes,
//    itself a node of the radix tree, halved by position below it; the
//    halvings are descended from the run to the one splitting at i + 1. A
//    range of at most leaf_size primitives is a leaf, so the node exists iff
//    its own range is larger (every ancestor's is larger still).
//  - subtree_reference(): a child range's reference (a leaf run, or the
//    inner node at its split), its leaf run size and its parent link.
//  - boxes_from_leaf(): the bottom-up box pass: one thread per leaf walks up
//    the parent links; an arrival counter per inner node lets only the
//    second child's thread go on (both children final), which writes the
//    node's box as union(left, right), the CPU refit's order; a walk that
//    reaches its cluster's root writes the cluster's box.
//  - enqueue_offset(): a lane's place among its warp's new tasks (a
//    warp-local prefix sum of 0, 1 or 2 children from two ballots), so a
//    warp enqueues with one atomicAdd (the top level's task queues).
//
// References (as morton::RawTree's): an inner node index, or kLeafRef | the
// sorted position of a leaf run's first primitive. Slots: the reference
// array holds 2 per inner node (2 * index + side, n - 1 nodes), then one per
// cluster (its root). No std:: here: plain pointers, RF_HDI.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::hlbvh2 {

inline constexpr uint32_t kLeafRef = 0x80000000u;  // == morton::kLeafRef (hlbvh2.cpp checks)
inline constexpr uint32_t kNoParent = 0xffffffffu;     // a position that starts no leaf; the top root's parent
inline constexpr uint32_t kClusterRootOf = 0x80000000u;  // | c: the parent link of cluster c's root
inline constexpr int kCodeBits = 30;
inline constexpr int kClusterShift = 15;           // clusters: the top 15 of 30 bits

RF_HDI int highest_bit(uint32_t x) {  // x != 0
#if defined(__CUDA_ARCH__)
    return 31 - __clz(static_cast<int>(x));
#else
    return 31 - __builtin_clz(x);
#endif
}

RF_HDI int popcount(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return __popc(x);
#else
    return __builtin_popcount(x);
#endif
}

// The split position mid in (first, end) of a range of >= 2 sorted codes.
RF_HDI uint32_t split_position(const uint32_t* codes, uint32_t first, uint32_t end) {
    const uint32_t differ = codes[first] ^ codes[end - 1];
    if (differ == 0) return first + (end - first) / 2;  // all codes equal: halve by position
    const int bit = highest_bit(differ);
    uint32_t lo = first + 1, hi = end - 1;  // codes[first] has a 0 there, codes[end-1] a 1
    while (lo < hi) {
        const uint32_t m = lo + (hi - lo) / 2;
        if ((codes[m] >> bit) & 1u) hi = m; else lo = m + 1;
    }
    return lo;
}

// A lane's offset among its warp's new tasks: `one_or_more` has the bits of
// lanes with >= 1 inner child, `two` of lanes with 2.
RF_HDI uint32_t enqueue_offset(uint32_t one_or_more, uint32_t two, int lane) {
    const uint32_t below = lane == 0 ? 0u : (0xffffffffu >> (32 - lane));
    return static_cast<uint32_t>(popcount(one_or_more & below) + popcount(two & below));
}
RF_HDI uint32_t enqueue_total(uint32_t one_or_more, uint32_t two) {
    return static_cast<uint32_t>(popcount(one_or_more) + popcount(two));
}

// Box growth with std::min/max semantics (as morton::box_union).
RF_HDI Box3f box_union(const Box3f& a, const Box3f& b) {
    Box3f r;
    r.lo = Vec3f(a.lo.x < b.lo.x ? a.lo.x : b.lo.x, a.lo.y < b.lo.y ? a.lo.y : b.lo.y, a.lo.z < b.lo.z ? a.lo.z : b.lo.z);
    r.hi = Vec3f(a.hi.x > b.hi.x ? a.hi.x : b.hi.x, a.hi.y > b.hi.y ? a.hi.y : b.hi.y, a.hi.z > b.hi.z ? a.hi.z : b.hi.z);
    return r;
}

// What the bottom-up box pass reads and writes.
struct BoxView {
    const uint32_t* refs;          // the reference array (slots as above)
    const uint8_t* leaf_runs;      // primitives per leaf, at the leaf's first position
    const uint32_t* order;         // sorted position -> triangle
    const Box3f* triangle_boxes;   // per triangle
    Box3f* inner_boxes;            // per inner node index
};

RF_HDI Box3f reference_box(const BoxView& v, uint32_t ref) {
    if ((ref & kLeafRef) == 0) return v.inner_boxes[ref];
    const uint32_t first = ref & ~kLeafRef;
    Box3f box = v.triangle_boxes[v.order[first]];
    for (uint32_t i = 1; i < v.leaf_runs[first]; ++i) box = box_union(box, v.triangle_boxes[v.order[first + i]]);
    return box;
}

// ---- The bottom trees in one launch ----

// The first position p in [lo, hi) with codes[p] >> shift >= key (hi when
// none); the codes are sorted.
RF_HDI uint32_t first_at_least(const uint32_t* codes, uint32_t lo, uint32_t hi, uint32_t key, int shift) {
    while (lo < hi) {
        const uint32_t m = lo + (hi - lo) / 2;
        if ((codes[m] >> shift) < key) lo = m + 1; else hi = m;
    }
    return lo;
}

// The sorted range [*first, *end) of inner node i (0 <= i < n - 1), the
// node of the forest that splits at position i + 1; false when there is
// none (i + 1 starts a cluster, or lies inside a leaf).
RF_HDI bool node_of_split(const uint32_t* codes, uint32_t n, uint32_t i, uint32_t leaf_size, uint32_t* first,
                          uint32_t* end) {
    const uint32_t left = codes[i], right = codes[i + 1];
    if ((left >> kClusterShift) != (right >> kClusterShift)) return false;  // i + 1 starts a cluster
    // Every code sharing the bits above the highest one where left and right
    // differ (a radix-tree node; <= 15 bits below the cluster's, so inside
    // it), or all 30 when they are equal (their run).
    const int shift = left == right ? 0 : highest_bit(left ^ right) + 1;
    const uint32_t key = left >> shift;
    uint32_t a = first_at_least(codes, 0, i, key, shift);
    uint32_t b = first_at_least(codes, i + 1, n, key + 1, shift);
    if (left != right) {
        *first = a;
        *end = b;
        return b - a > leaf_size;
    }
    // The run's halvings by position, down to the one at i + 1.
    const uint32_t mid = i + 1;
    while (b - a > leaf_size) {
        const uint32_t m = a + (b - a) / 2;
        if (m == mid) {
            *first = a;
            *end = b;
            return true;
        }
        if (mid < m) b = m; else a = m;
    }
    return false;
}

// What the bottom trees' launch writes: refs (slots as above), the leaf
// runs' sizes at their first positions, and the parent links for the box
// pass: inner_parent per inner node index, leaf_parent per leaf's first
// position (kNoParent elsewhere: set before), a cluster root's parent
// being kClusterRootOf | its cluster.
struct BottomTrees {
    uint32_t* refs;
    uint8_t* leaf_runs;
    uint32_t* inner_parent;  // n - 1
    uint32_t* leaf_parent;   // n
};

// The reference of the subtree over sorted range [a, b) (a leaf run, or the
// inner node at its split), recording its leaf run and `parent` as its parent.
RF_HDI uint32_t subtree_reference(const uint32_t* codes, uint32_t a, uint32_t b, uint32_t leaf_size, uint32_t parent,
                                  const BottomTrees& out) {
    if (b - a <= leaf_size) {
        out.leaf_runs[a] = static_cast<uint8_t>(b - a);
        out.leaf_parent[a] = parent;
        return kLeafRef | a;
    }
    const uint32_t index = split_position(codes, a, b) - 1;
    out.inner_parent[index] = parent;
    return index;
}

// One thread per split position i (0 <= i < n - 1): inner node i, if there
// is one, writes its children's references. 1 <= leaf_size <= 255.
RF_HDI void build_split_node(const uint32_t* codes, uint32_t n, uint32_t i, uint32_t leaf_size,
                             const BottomTrees& out) {
    uint32_t first = 0, end = 0;
    if (!node_of_split(codes, n, i, leaf_size, &first, &end)) return;
    out.refs[2 * i] = subtree_reference(codes, first, i + 1, leaf_size, i, out);
    out.refs[2 * i + 1] = subtree_reference(codes, i + 1, end, leaf_size, i, out);
}

// One thread per cluster c over [first, end): its root's reference.
RF_HDI void build_cluster_root(const uint32_t* codes, uint32_t n, uint32_t c, uint32_t first, uint32_t end,
                               uint32_t leaf_size, const BottomTrees& out) {
    out.refs[2 * (n - 1) + c] = subtree_reference(codes, first, end, leaf_size, kClusterRootOf | c, out);
}

// ---- The bottom trees' boxes in one launch ----

struct BottomBoxPass {
    BoxView boxes;                // inner_boxes written
    const uint32_t* inner_parent;
    const uint32_t* leaf_parent;
    uint32_t* arrivals;           // n - 1, zero before the pass
    Box3f* cluster_boxes;         // per cluster, written
};

// The box of a reference another thread may have just written (inner boxes
// read past L1, karras::load_shared_box).
RF_HDI Box3f final_reference_box(const BoxView& v, uint32_t ref) {
    return (ref & kLeafRef) != 0 ? reference_box(v, ref) : karras::load_shared_box(&v.inner_boxes[ref]);
}

// The walk from the leaf at sorted position `position` (nothing when no leaf
// starts there). `Arrival` provides arrive(uint32_t*), returning the count
// before (karras::AtomicArrival; the tests inject others).
template <class Arrival>
RF_HDI void boxes_from_leaf(const BottomBoxPass& p, uint32_t position) {
    uint32_t parent = p.leaf_parent[position];
    if (parent == kNoParent) return;
    uint32_t from = kLeafRef | position;
    Box3f box = reference_box(p.boxes, from);
    while ((parent & kClusterRootOf) == 0) {
        if (Arrival::arrive(&p.arrivals[parent]) == 0) return;  // the sibling's walk goes on
        const uint32_t left = p.boxes.refs[2 * parent], right = p.boxes.refs[2 * parent + 1];
        const bool from_left = left == from;
        const Box3f other = final_reference_box(p.boxes, from_left ? right : left);
        box = from_left ? box_union(box, other) : box_union(other, box);
        p.boxes.inner_boxes[parent] = box;
        from = parent;
        parent = p.inner_parent[parent];
    }
    p.cluster_boxes[parent & ~kClusterRootOf] = box;
}

}  // namespace rf::hlbvh2
