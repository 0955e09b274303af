// The per-task steps of HLBVH2's bottom levels (Garanzha 2014, dissertation
// ch. 5, "BVH construction with binary search and work queues"; Garanzha,
// Pantaleoni and McAllister, HPG 2011), written once for both backends: the
// CPU builder (hlbvh2.cpp) recurses over them, the CUDA builder
// (backend/cuda/hlbvh2_build.cu) runs one task per thread, one tree level
// per launch, with work queues.
//
//  - split_position(): a node over sorted range [a, b) of 30-bit codes
//    splits where the highest bit in which codes[a] and codes[b-1] differ
//    turns from 0 to 1 (binary search for the first 1: the codes share every
//    higher bit, so that bit is 0s then 1s); all codes equal: halve by position.
//  - process_task(): one queue task. A range of at most `leaf_size`
//    primitives is a leaf; otherwise the task becomes inner node mid - 1
//    (each split position occurs once in the whole forest, so node indices
//    are fixed by the input, not by scheduling), writes its leaf children's
//    references at once and hands back its inner children as new tasks.
//    Every task writes its own reference into its parent's slot.
//  - enqueue_offset(): a lane's place among its warp's new tasks (a
//    warp-local prefix sum of 0, 1 or 2 children from two ballots), so a
//    warp enqueues with one atomicAdd.
//  - node_box(): the box of an inner node from its children, for the
//    bottom-up pass that runs level by level, deepest first.
//
// References (as morton::RawTree's): an inner node index, or kLeafRef | the
// sorted position of a leaf run's first primitive. Slots: the reference
// array holds 2 per inner node (2 * index + side, n - 1 nodes), then one per
// cluster (its root). No std:: here: plain pointers, RF_HDI.
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::hlbvh2 {

inline constexpr uint32_t kLeafRef = 0x80000000u;  // == morton::kLeafRef (hlbvh2.cpp checks)
inline constexpr uint32_t kNoNode = 0xffffffffu;   // a level entry that made no inner node
inline constexpr int kCodeBits = 30;
inline constexpr int kClusterShift = 15;           // clusters: the top 15 of 30 bits

// One queue entry: sorted range [first, end) and the slot its reference goes to.
struct Task {
    uint32_t first;
    uint32_t end;
    uint32_t slot;
};

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

// Processes `task`: writes its reference to refs[task.slot] and, for an
// inner node, its leaf children's references to refs[2 * node + side];
// inner children go to inner_children[0 ..) and their number is returned
// (0, 1 or 2). *node receives the inner node's index, or kNoNode for a leaf.
// Each leaf's size goes to leaf_runs[first] when leaf_runs is not null.
// 1 <= leaf_size <= 255.
RF_HDI uint32_t process_task(const uint32_t* codes, const Task& task, uint32_t leaf_size, uint32_t* refs,
                             uint8_t* leaf_runs, Task* inner_children, uint32_t* node) {
    if (task.end - task.first <= leaf_size) {
        refs[task.slot] = kLeafRef | task.first;
        if (leaf_runs != nullptr) leaf_runs[task.first] = static_cast<uint8_t>(task.end - task.first);
        *node = kNoNode;
        return 0;
    }
    const uint32_t mid = split_position(codes, task.first, task.end);
    const uint32_t index = mid - 1;
    refs[task.slot] = index;
    *node = index;
    const Task halves[2] = {{task.first, mid, 2 * index}, {mid, task.end, 2 * index + 1}};
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first <= leaf_size) {
            refs[halves[side].slot] = kLeafRef | halves[side].first;
            if (leaf_runs != nullptr) {
                leaf_runs[halves[side].first] = static_cast<uint8_t>(halves[side].end - halves[side].first);
            }
        } else {
            inner_children[inner++] = halves[side];
        }
    }
    return inner;
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

// Inner node `index`'s box from its children's (final: deeper level, or leaves).
RF_HDI void node_box(const BoxView& v, uint32_t index) {
    v.inner_boxes[index] = box_union(reference_box(v, v.refs[2 * index]), reference_box(v, v.refs[2 * index + 1]));
}

}  // namespace rf::hlbvh2
