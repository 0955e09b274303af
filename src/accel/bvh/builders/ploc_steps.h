// Per-cluster steps of PLOC (Meister and Bittner 2018, "Parallel
// Locally-Ordered Clustering for Bounding Volume Hierarchy Construction",
// IEEE TVCG), written once for both backends: the CPU builder (ploc.cpp)
// loops over them, the CUDA builder (backend/cuda/ploc_build.cu) runs them
// one thread per cluster, and tests/ploc_device_logic_test.cpp replays the
// device schedule on the CPU.
//
//  - merged_area(): the distance function of sec. 3 (surface area of the
//    merged box, here its half), rounded as the CPU rounds it (no fused
//    multiply-add on the device), and symmetric, so a distance computed once
//    serves both ends of a pair (sec. 4.2).
//  - neighbour_key(): the nearest-neighbour search of sec. 4.1 as a minimum
//    of 64-bit keys: (area, then the tie rule of closer_pair()). A total
//    order on pairs makes the globally closest pair mutual, so every
//    iteration merges; being a minimum, it can be taken in any order (one
//    atomicMin per distance on the device).
//  - nearest_neighbour(): the plain per-cluster search over +-radius.
//  - window_pairs_from(): the search of sec. 4.2 for a block of clusters
//    whose boxes, with radius more on each side, sit in shared memory: every
//    pair with an end in the block is evaluated once and recorded at both ends.
//  - compaction_flags(), place_cluster(), compact_cluster(): the merge of
//    mutual neighbours i < j into a new node at position i and the
//    compaction of sec. 4.3 by one exclusive prefix sum over the clusters
//    (survivors, merges): new positions and new node numbers both follow
//    the cluster order, whatever blocks the sum is computed in.
//  - LoopState, next_state(): the iteration loop's state kept on the device
//    (count, nodes made, iterations, a fault), so no iteration's count has
//    to reach the host: every kernel of an iteration reads it, one thread
//    advances it from the iteration's flag total.
//  - thread_chunk(): the contiguous clusters one thread of the single-block
//    tail owns, so a block-wide scan of per-thread sums is in cluster order.
// No std:: here: plain pointers and fixed-size values.
#pragma once

#include <cstdint>
#include <cstring>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::ploc {

// Child references as in morton_tree.h: inner node, or kLeafRef | sorted position.
inline constexpr uint32_t kLeafRef = karras::kLeafRef;
inline constexpr uint32_t kMaxRadius = 1u << 16;  // the search distance fits neighbour_key's 17 bits
inline constexpr uint64_t kNoNeighbour = ~uint64_t{0};  // larger than every key

RF_HDI uint32_t clamp_radius(int radius) {
    return radius < 1 ? 1u : static_cast<uint32_t>(radius) > kMaxRadius ? kMaxRadius : static_cast<uint32_t>(radius);
}

// Half the surface area of the union of two boxes: x y + y z + z x, each
// product and sum rounded once, in this order, on both backends.
RF_HDI float merged_area(const Box3f& a, const Box3f& b) {
    const Box3f m = karras::box_union(a, b);
    const float x = m.hi.x - m.lo.x, y = m.hi.y - m.lo.y, z = m.hi.z - m.lo.z;
    return add_rn(add_rn(mul_rn(x, y), mul_rn(y, z)), mul_rn(z, x));
}

// The tie rule between candidates j and k of cluster i at equal areas, the
// same from both ends of a pair so that the order on pairs is total: nearer
// positions first, then pairs starting at an even position, then the lower
// start. Among identical boxes (duplicate triangles) this pairs (0,1),
// (2,3), ..., halving them every iteration; "lowest position first" would
// merge one pair per iteration. neighbour_key() encodes it; kept as the
// definition the tests check the key against.
RF_HDI bool closer_pair(uint32_t i, uint32_t j, uint32_t k) {
    const uint32_t dj = j > i ? j - i : i - j, dk = k > i ? k - i : i - k;
    if (dj != dk) return dj < dk;
    const uint32_t sj = i < j ? i : j, sk = i < k ? i : k;
    if ((sj & 1u) != (sk & 1u)) return (sj & 1u) == 0;
    return sj < sk;
}

// At distance d from i there are two candidates, i - d and i + d; the tie
// rule prefers the right one exactly when i is even and i - d odd.
RF_HDI bool right_preferred(uint32_t i, uint32_t d) { return (i & 1u) == 0 && (d & 1u) != 0; }

// The order of candidate j for cluster i as one integer: the area's bits
// (non-negative floats order as their bits; zeros of either sign become 0,
// NaN sorts last), then the distance, then the side the tie rule prefers.
RF_HDI uint64_t neighbour_key(float area, uint32_t i, uint32_t j) {
    uint32_t bits;
    memcpy(&bits, &area, sizeof bits);
    bits = area > 0.0f ? bits : area == 0.0f ? 0u : 0xffffffffu;
    const uint32_t d = j > i ? j - i : i - j;
    const uint32_t side = (j > i) == right_preferred(i, d) ? 0u : 1u;
    return (uint64_t{bits} << 32) | (uint64_t{d - 1} << 1) | side;
}

// The candidate a key names.
RF_HDI uint32_t neighbour_from_key(uint32_t i, uint64_t key) {
    const uint32_t d = static_cast<uint32_t>((key >> 1) & 0x1ffffu) + 1;
    const bool right = ((key & 1u) == 0) == right_preferred(i, d);
    return right ? i + d : i - d;
}

// Cluster i's nearest neighbour among positions i - radius .. i + radius of
// `count` >= 2 clusters.
RF_HDI uint32_t nearest_neighbour(const Box3f* boxes, uint32_t count, uint32_t radius, uint32_t i) {
    const Box3f box = boxes[i];
    const uint32_t begin = i > radius ? i - radius : 0;
    const uint32_t end = count - i > radius ? i + radius + 1 : count;
    uint64_t best = kNoNeighbour;
    for (uint32_t j = begin; j != end; ++j) {
        if (j == i) continue;
        const uint64_t key = neighbour_key(merged_area(box, boxes[j]), i, j);
        best = key < best ? key : best;
    }
    return neighbour_from_key(i, best);
}

// A block's clusters [block_begin, block_end) and the window of positions
// [begin, end) it needs: radius more on each side, within the clusters.
struct Window {
    uint32_t begin, end;
    uint32_t block_begin, block_end;
};

RF_HDI Window block_window(uint32_t block_begin, uint32_t block_size, uint32_t count, uint32_t radius) {
    Window w;
    w.block_begin = block_begin;
    w.block_end = count - block_begin > block_size ? block_begin + block_size : count;
    w.begin = block_begin > radius ? block_begin - radius : 0;
    w.end = count - w.block_end > radius ? w.block_end + radius : count;
    return w;
}

// The pairs (p, p + d), d = 1 .. radius, inside the window with an end in
// the block, for one left end p in [w.begin, w.block_end); `window_boxes`
// holds the boxes of positions w.begin .. w.end - 1. Each distance is
// computed once and offered to both ends that lie in the block:
// record(position - w.block_begin, key). Over all p, every pair with an end
// in the block is evaluated exactly once.
template <class Record>
RF_HDI void window_pairs_from(const Box3f* window_boxes, const Window& w, uint32_t radius, uint32_t p,
                              Record& record) {
    const Box3f box = window_boxes[p - w.begin];
    const uint32_t first = p < w.block_begin ? w.block_begin - p : 1;  // nearer partners are outside the block
    for (uint32_t d = first; d <= radius && p + d < w.end; ++d) {
        const uint32_t q = p + d;
        const float area = merged_area(box, window_boxes[q - w.begin]);
        if (p >= w.block_begin) record(p - w.block_begin, neighbour_key(area, p, q));
        if (q < w.block_end) record(q - w.block_begin, neighbour_key(area, q, p));
    }
}

// What cluster i contributes to the prefix sum: one survivor (high word)
// when it stays (no mutual neighbour) or becomes the merged node (the lower
// of a mutual pair), and one merge (low word) in the latter case.
RF_HDI uint64_t compaction_flags(const uint32_t* neighbour, uint32_t i) {
    const uint32_t j = neighbour[i];
    const bool mutual = neighbour[j] == i;
    const uint64_t survives = !mutual || i < j, merges = mutual && i < j;
    return (survives << 32) | merges;
}

struct Placement {
    bool survives;     // position i leaves a cluster in the next iteration
    bool merges;       // ... and it is a new node over i and `partner`
    uint32_t partner;  // the mutual neighbour (merges only)
    uint32_t position; // its position in the next iteration (survives only)
    uint32_t node;     // the new node's number (merges only)
};

// Cluster i's fate, from `prefix`, the exclusive sum of compaction_flags
// over the clusters before i; new nodes are numbered from `next_node`.
RF_HDI Placement place_cluster(const uint32_t* neighbour, uint32_t i, uint64_t prefix, uint32_t next_node) {
    const uint64_t flags = compaction_flags(neighbour, i);
    Placement p;
    p.survives = (flags >> 32) != 0;
    p.merges = (flags & 1u) != 0;
    p.partner = neighbour[i];
    p.position = static_cast<uint32_t>(prefix >> 32);
    p.node = next_node + static_cast<uint32_t>(prefix & 0xffffffffu);
    return p;
}

// The clusters of one iteration and the next, and the tree being built.
struct ClusterArrays {
    const uint32_t* refs;   // child reference of each cluster
    const Box3f* boxes;     // its box
    uint32_t* next_refs;    // the next iteration's
    Box3f* next_boxes;
    uint32_t* children;     // 2 per node: left (the lower position), right
    Box3f* node_boxes;      // per node, or nullptr
};

// The merge and compaction step of cluster i: a survivor moves to its new
// position; the lower end of a mutual pair writes the new node (children
// in position order, box = their union, as RawTree::finalize computes it)
// and puts it at its own new position.
RF_HDI void compact_cluster(const ClusterArrays& a, const uint32_t* neighbour, uint32_t i, uint64_t prefix,
                            uint32_t next_node) {
    const Placement p = place_cluster(neighbour, i, prefix, next_node);
    if (!p.survives) return;
    if (!p.merges) {
        a.next_refs[p.position] = a.refs[i];
        a.next_boxes[p.position] = a.boxes[i];
        return;
    }
    const Box3f box = karras::box_union(a.boxes[i], a.boxes[p.partner]);
    a.children[2 * uint64_t{p.node}] = a.refs[i];
    a.children[2 * uint64_t{p.node} + 1] = a.refs[p.partner];
    if (a.node_boxes != nullptr) a.node_boxes[p.node] = box;
    a.next_refs[p.position] = p.node;
    a.next_boxes[p.position] = box;
}

// The clustering loop's state, on the device between the kernels.
struct LoopState {
    uint32_t count;       // clusters left
    uint32_t next_node;   // nodes made so far (the next node's number)
    uint32_t iterations;  // iterations done; their parity picks the cluster buffers
    uint32_t fault;       // 0, kFaultNoProgress or kFaultTailOverflow
    uint32_t fault_survivors, fault_merges;  // what the faulty iteration reported (the overflow: the count)
};

// Iteration `iterations` merged nothing or lost clusters.
inline constexpr uint32_t kFaultNoProgress = 1;
// The single-block tail was handed more clusters than it holds.
inline constexpr uint32_t kFaultTailOverflow = 2;

RF_HDI LoopState first_state(uint32_t n) { return LoopState{n, 0u, 0u, 0u, 0u, 0u}; }

// The grid-wide kernels run an iteration only while the count is above the
// single-block tail's capacity (and nothing faulted); otherwise the launch
// is a no-op and the state passes through unchanged.
RF_HDI bool grid_iteration_runs(const LoopState& s, uint32_t tail_capacity) {
    return s.fault == 0 && s.count > tail_capacity;
}

// The state after an iteration over s.count clusters whose compaction flags
// sum to `total` ((survivors << 32) | merges). The closest pair is always
// mutual, so an iteration without merges, or with survivors that do not
// add up, is a device fault: recorded, never looped on.
RF_HDI LoopState next_state(const LoopState& s, uint64_t total) {
    const uint32_t survivors = static_cast<uint32_t>(total >> 32), merges = static_cast<uint32_t>(total);
    LoopState r = s;
    if (merges == 0 || survivors != s.count - merges) {
        r.fault = kFaultNoProgress;
        r.fault_survivors = survivors;
        r.fault_merges = merges;
        return r;
    }
    r.count = survivors;
    r.next_node += merges;
    r.iterations += 1;
    return r;
}

// next_state(), and the iteration's node count into iteration_nodes (when
// given: one thread of the kernel that advances the state writes it).
RF_HDI LoopState commit_iteration(const LoopState& s, uint64_t total, uint32_t* iteration_nodes) {
    const LoopState r = next_state(s, total);
    if (r.fault == 0 && iteration_nodes != nullptr) iteration_nodes[s.iterations] = r.next_node - s.next_node;
    return r;
}

// The state the single-block tail starts from: s, or an overflow fault
// when s holds more than `capacity` clusters.
RF_HDI LoopState tail_start(const LoopState& s, uint32_t capacity) {
    LoopState r = s;
    if (r.fault == 0 && r.count > capacity) {
        r.fault = kFaultTailOverflow;
        r.fault_survivors = r.count;
        r.fault_merges = 0;
    }
    return r;
}

// Clusters [begin, end) of thread t of `threads` over `count` clusters:
// contiguous chunks in thread order (empty for the threads past the end).
struct Chunk {
    uint32_t begin, end;
};

RF_HDI Chunk thread_chunk(uint32_t count, uint32_t threads, uint32_t t) {
    const uint32_t per = (count + threads - 1) / threads;
    const uint64_t begin = uint64_t{per} * t, end = begin + per;
    Chunk c;
    c.begin = begin < count ? static_cast<uint32_t>(begin) : count;
    c.end = end < count ? static_cast<uint32_t>(end) : count;
    return c;
}

}  // namespace rf::ploc
