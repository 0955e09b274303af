// Per-node steps of Karras 2012, "Maximizing Parallelism in the Construction
// of BVHs, Octrees, and k-d Trees" (HPG 2012), written once for both
// backends: the CPU LBVH (lbvh.cpp) loops over them, the CUDA builder
// (backend/cuda/lbvh_build.cu) runs one thread per node or leaf.
//
//  - delta(): length of the common prefix of the keys (code ++ sorted
//    position) at two sorted positions; appending the position makes every
//    key distinct, so duplicate codes still give a binary radix tree (sec. 4).
//  - build_inner(): inner node i of n - 1 finds, independently of all other
//    nodes, the direction of its range (towards the neighbour sharing the
//    longer prefix), the range's other end (exponential then binary search)
//    and its split (binary search for the last position sharing more than the
//    node's prefix); its children are the inner nodes or leaves numbered by the
//    split, and it records itself as their parent (Karras fig. 4).
//  - propagate_boxes_from_leaf(): the bottom-up box pass of sec. 4: every
//    leaf walks up; an atomic counter per inner node lets only the second
//    arriving thread continue (both children are final then) and compute the
//    node's box as the union of its children's.
//
// Child references are an inner node index, or kLeafRef | sorted position.
// No std:: here: plain pointers, RF_HDI, intrinsics picked per compiler.
#pragma once

#include <cstdint>

#include "core/assert.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

#if defined(__CUDACC__)
#include <cuda/atomic>  // AtomicArrival's atomic_ref
#endif

namespace rf::karras {

// The same encoding as morton::kLeafRef (lbvh.cpp checks it), so a Karras
// tree's child pairs are a morton::RawTree's as they are.
inline constexpr uint32_t kLeafRef = 0x80000000u;
inline constexpr uint32_t kNoParent = 0xffffffffu;  // the root's parent

RF_HDI bool is_leaf_ref(uint32_t ref) { return (ref & kLeafRef) != 0; }

// Leading zero bits; x != 0.
RF_HDI int leading_zeros(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return __clz(static_cast<int>(x));
#else
    return __builtin_clz(x);
#endif
}
RF_HDI int leading_zeros(uint64_t x) {
#if defined(__CUDA_ARCH__)
    return __clzll(static_cast<long long>(x));
#else
    return __builtin_clzll(x);
#endif
}

// Length of the common prefix of (code, position) at sorted positions i and
// j of n keys; -1 when j is outside the array. i is inside, i != j.
template <class Key>
RF_HDI int delta(const Key* keys, uint32_t n, int64_t i, int64_t j) {
    if (static_cast<uint64_t>(j) >= n) return -1;
    const Key a = keys[i], b = keys[j];
    const uint32_t positions = static_cast<uint32_t>(i ^ j);  // != 0
    if constexpr (sizeof(Key) == 4) {
        // Codes above positions in one 64-bit word: the code prefix where the
        // codes differ, else 32 + the position prefix.
        return leading_zeros((static_cast<uint64_t>(a ^ b) << 32) | positions);
    } else {
        if (a != b) return leading_zeros(static_cast<uint64_t>(a ^ b));
        return 64 + leading_zeros(positions);
    }
}

// Builds inner node `index` (0 .. n-2, root 0; n >= 2) over the n sorted
// keys: writes its two child references to child[0..1] and, when the parent
// arrays are given, itself as their parent (inner_parent: n - 1 entries,
// leaf_parent: n entries). The root's parent is set to kNoParent by node 0,
// which is never anybody's child.
template <class Key>
RF_HDI void build_inner(const Key* keys, uint32_t n, uint32_t index, uint32_t* child, uint32_t* inner_parent,
                        uint32_t* leaf_parent) {
    const int64_t i = index;
    // Direction of the range: towards the neighbour sharing the longer prefix.
    const int next = delta(keys, n, i, i + 1), previous = delta(keys, n, i, i - 1);
    const int d = next - previous > 0 ? 1 : -1;
    const int delta_min = d > 0 ? previous : next;  // delta(i, i - d)
    // Upper bound on the range length, then its exact other end j.
    int64_t max_length = 2;
    while (delta(keys, n, i, i + max_length * d) > delta_min) max_length *= 2;
    int64_t length = 0;
    for (int64_t step = max_length / 2; step >= 1; step /= 2) {
        if (delta(keys, n, i, i + (length + step) * d) > delta_min) length += step;
    }
    const int64_t j = i + length * d;
    // Split: the last position sharing more than the node's prefix with i.
    const int delta_node = delta(keys, n, i, j);
    int64_t split = 0;
    int64_t step = length;
    do {
        step = (step + 1) / 2;
        if (delta(keys, n, i, i + (split + step) * d) > delta_node) split += step;
    } while (step > 1);
    const int64_t gamma = i + split * d + (d < 0 ? d : 0);

    RF_ASSERT(gamma >= 0 && gamma + 1 < int64_t(n), "a Karras split outside the key range");
    const uint32_t g = static_cast<uint32_t>(gamma);
    const bool left_is_leaf = (i < j ? i : j) == gamma;
    const bool right_is_leaf = (i > j ? i : j) == gamma + 1;
    child[0] = left_is_leaf ? (kLeafRef | g) : g;
    child[1] = right_is_leaf ? (kLeafRef | (g + 1)) : g + 1;
    if (inner_parent != nullptr) {
        if (index == 0) inner_parent[0] = kNoParent;
        (left_is_leaf ? leaf_parent : inner_parent)[g] = index;
        (right_is_leaf ? leaf_parent : inner_parent)[g + 1] = index;
    }
}

// Box growth with the semantics of std::min/max, so boxes come out
// bit-identical on both backends (morton::box_union is this one); inputs
// are finite.
RF_HDI Box3f box_union(const Box3f& a, const Box3f& b) {
    Box3f r;
    r.lo = Vec3f(a.lo.x < b.lo.x ? a.lo.x : b.lo.x, a.lo.y < b.lo.y ? a.lo.y : b.lo.y, a.lo.z < b.lo.z ? a.lo.z : b.lo.z);
    r.hi = Vec3f(a.hi.x > b.hi.x ? a.hi.x : b.hi.x, a.hi.y > b.hi.y ? a.hi.y : b.hi.y, a.hi.z > b.hi.z ? a.hi.z : b.hi.z);
    return r;
}

// Reads a box another thread wrote. On the device the load bypasses L1,
// which is not coherent across SMs and may hold a stale line around it.
RF_HDI Box3f load_shared_box(const Box3f* p) {
#if defined(__CUDA_ARCH__)
    const float* f = reinterpret_cast<const float*>(p);
    Box3f b;
    b.lo = Vec3f(__ldcg(f + 0), __ldcg(f + 1), __ldcg(f + 2));
    b.hi = Vec3f(__ldcg(f + 3), __ldcg(f + 4), __ldcg(f + 5));
    return b;
#else
    return *p;
#endif
}

// The arrival counter of the box pass: returns the count before this
// arrival. One acquire-release read-modify-write at device scope makes the
// box a thread wrote before arriving visible to the thread that arrives
// second (the release half) and the first one's box to it (the acquire
// half), without the two full __threadfence()s on the walk's critical path.
struct AtomicArrival {
    RF_HDI static uint32_t arrive(uint32_t* counter) {
#if defined(__CUDA_ARCH__)
        return ::cuda::atomic_ref<uint32_t, ::cuda::thread_scope_device>(*counter).fetch_add(
            1u, ::cuda::std::memory_order_acq_rel);
#else
        return __atomic_fetch_add(counter, 1u, __ATOMIC_ACQ_REL);
#endif
    }
};

// What the box pass reads and writes; every array is indexed as in build_inner.
struct BoxPassView {
    const uint32_t* children;      // 2 per inner node
    const uint32_t* inner_parent;  // n - 1
    const uint32_t* leaf_parent;   // n
    const Box3f* primitive_boxes;  // per triangle when `order` is given, else per sorted position
    const uint32_t* order;         // sorted position -> triangle, or nullptr
    Box3f* inner_boxes;            // n - 1, written
    uint32_t* arrivals;            // n - 1, zero before the pass
};

RF_HDI Box3f leaf_box(const BoxPassView& tree, uint32_t position) {
    return tree.primitive_boxes[tree.order != nullptr ? tree.order[position] : position];
}

// Leaf `position`'s walk towards the root (Karras sec. 4). The first thread to
// reach a node stops there: its sibling subtree may not be final yet; the
// second computes the node's box (left child first, as the CPU refit does)
// and goes on. Every inner node's box is written exactly once. `Arrival`
// provides arrive(uint32_t*) (AtomicArrival; the tests inject others).
template <class Arrival>
RF_HDI void propagate_boxes_from_leaf(const BoxPassView& tree, uint32_t position) {
    uint32_t from = kLeafRef | position;  // the child this thread comes from
    Box3f box = leaf_box(tree, position);  // and its box, kept in registers
    uint32_t node = tree.leaf_parent[position];
    while (node != kNoParent) {
        if (Arrival::arrive(&tree.arrivals[node]) == 0) return;
        const uint32_t left = tree.children[2 * node], right = tree.children[2 * node + 1];
        const bool from_left = left == from;
        const uint32_t sibling = from_left ? right : left;
        const Box3f other = is_leaf_ref(sibling) ? leaf_box(tree, sibling & ~kLeafRef)
                                                 : load_shared_box(&tree.inner_boxes[sibling]);
        box = from_left ? box_union(box, other) : box_union(other, box);
        tree.inner_boxes[node] = box;
        from = node;
        node = tree.inner_parent[node];
    }
}

}  // namespace rf::karras
