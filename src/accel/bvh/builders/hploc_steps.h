// The steps of H-PLOC (Benthin, Meister, Barczak, Mohan and Vaidyanathan,
// "H-PLOC: Hierarchical Parallel Locally-Ordered Clustering for Bounding
// Volume Hierarchy Construction", HPG 2024), written once for both backends
// over a small warp abstraction: the CUDA builder (backend/cuda/hploc_build.cu)
// runs them on real warps (shuffles, ballots, one thread per leaf), the CPU
// builder (hploc.cpp) and tests/hploc_device_logic_test.cpp on a
// SimulatedWarp, whose 32 lanes are a loop.
//
// The paper's algorithm (its single-kernel build; section numbers are not
// quoted here, this file was written from the algorithm's description), one
// launch after the sort:
//  - every thread starts at its leaf, range [i, i], and climbs the implicit
//    LBVH bottom-up in Apetrei's single pass (Apetrei 2014, "Fast and Simple
//    Agglomerative LBVH Construction"): a range [l, r]'s parent lies at the
//    boundary (l - 1 | l) or (r | r + 1) whose neighbouring Morton keys
//    share the longer prefix (karras::delta, keys extended by the position);
//    both children of a node meet at its boundary slot by an atomic
//    exchange: the first to come leaves its range's far end there and
//    stops, the second takes it and goes on with the union (climb());
//  - a range's clusters sit at the front of its slots in the cluster array,
//    the rest of its first kMergeThreshold slots emptied (kNoCluster); a
//    leaf range is its leaf. When a thread's range spans more than
//    kMergeThreshold leaves, or is the root, its warp loads the clusters
//    of both children (at most kMergeThreshold each: at most one warp's
//    worth) and runs PLOC on them (Meister and Bittner 2018: nearest
//    neighbour within the radius along the Morton order by the area of the
//    merged box, merge of mutual neighbours, compaction) until at most
//    kMergeThreshold clusters are left, or one at the root; it stores them
//    back at the range's front (process_range());
//  - the warp serves its lanes' ranges one after the other, lowest lane
//    first, each round of climbing (warp_round()).
// The clusters a range keeps depend only on the clusters its children kept,
// so the tree depends on the Morton order alone, not on which thread or
// warp came second or in which order warps ran: the schedule changes only
// the node numbers, and a node is always numbered after its children (a
// parent's merges happen after its children's). The PLOC step reuses
// ploc_steps.h's distance (merged_area, rounded alike on both backends) and
// its tie rule (neighbour_key over lane positions), so the globally
// closest pair of a range is mutual and every PLOC step merges.
//
// A Warp provides (see SimulatedWarp): Lanes<T> (one T per lane, lane
// indexed), for_each_lane(f), ballot(pred), shuffle(values, source),
// read_lane(values, lane), add_once(counter, value) and sync(). Every call
// but for_each_lane's body is made by all lanes together (no divergence).
// A Memory provides: load_ref / store_ref (cluster slots), box(ref),
// write_node(node, left, right, box), exchange(slot, value) and publish()
// (makes the stores visible before the next exchange).
// No std:: here: plain pointers, RF_HDI.
#pragma once

#include <cstdint>

#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::hploc {

inline constexpr uint32_t kLeafRef = karras::kLeafRef;       // child references as morton::RawTree's
inline constexpr uint32_t kWarpLanes = 32;
inline constexpr uint32_t kMergeThreshold = kWarpLanes / 2;  // clusters a range passes up (half a warp)
inline constexpr uint32_t kMaxRadius = kWarpLanes - 1;       // farther lanes never hold a cluster
inline constexpr uint32_t kNoCluster = 0xffffffffu;          // an emptied cluster slot
inline constexpr uint32_t kNoRangeEnd = 0xffffffffu;         // a boundary slot no child has reached yet

RF_HDI uint32_t clamp_radius(int radius) {
    return radius < 1 ? 1u : static_cast<uint32_t>(radius) > kMaxRadius ? kMaxRadius : static_cast<uint32_t>(radius);
}

// A thread's range of sorted positions [left, right]; after a climb, its
// right child starts at `split`.
struct Range {
    uint32_t left = 0, right = 0, split = 0;
    bool active = false;  // still climbing
};

RF_HDI uint32_t range_size(const Range& r) { return r.right - r.left + 1; }

// The lane's range at the start: its leaf, when it has one.
RF_HDI Range leaf_range(uint32_t position, uint32_t n) {
    Range r;
    r.left = r.right = r.split = position;
    r.active = position < n;
    return r;
}

// Apetrei's rule: the parent of [left, right] (not the whole array) lies at
// the boundary whose keys share the longer prefix (never equal: the keys
// extended by the position are distinct, and a radix tree's node differs
// from its two outer neighbours at different bits).
RF_HDI bool parent_on_right(const uint64_t* keys, uint32_t n, uint32_t left, uint32_t right) {
    if (left == 0) return true;
    if (right == n - 1) return false;
    return karras::delta(keys, n, right, right + 1) > karras::delta(keys, n, left - 1, left);
}

// One step up from range r (n >= 2, r not the root): at boundary slot b
// (between positions b and b + 1; n - 1 slots, kNoRangeEnd at the start)
// the left child leaves its left end, the right child its right end. The
// first to come stops (returns false); the second gets the sibling's far end
// and takes the parent's range.
template <class Memory>
RF_HDI bool climb(const uint64_t* keys, uint32_t n, uint32_t* boundary_slots, Memory& memory, Range& r) {
    if (parent_on_right(keys, n, r.left, r.right)) {
        const uint32_t far_end = memory.exchange(&boundary_slots[r.right], r.left);
        if (far_end == kNoRangeEnd) return false;
        r.split = r.right + 1;
        r.right = far_end;
    } else {
        const uint32_t far_end = memory.exchange(&boundary_slots[r.left - 1], r.right);
        if (far_end == kNoRangeEnd) return false;
        r.split = r.left;
        r.left = far_end;
    }
    return true;
}

template <class Warp, class T>
using LanesOf = typename Warp::template Lanes<T>;

RF_HDI uint32_t lanes_below(uint32_t lane) { return lane == 0 ? 0u : 0xffffffffu >> (kWarpLanes - lane); }

// The lane of the n-th (from 0) set bit of mask; `none` when it has fewer.
RF_HDI uint32_t nth_set_lane(uint32_t mask, uint32_t n, uint32_t none) {
#if defined(__CUDA_ARCH__)
    const int lane = __fns(mask, 0, static_cast<int>(n) + 1);
    return lane < 0 ? none : static_cast<uint32_t>(lane);
#else
    for (; n > 0 && mask != 0; --n) mask &= mask - 1;  // drop the n lowest set bits
    return mask != 0 ? static_cast<uint32_t>(__builtin_ctz(mask)) : none;
#endif
}

// Every lane's nearest neighbour among the `count` clusters in lanes 0 ..
// count - 1, within `radius` lanes: ploc::nearest_neighbour's choice. Each
// pair's area is computed once, by its left lane, and handed to its right
// lane by a shuffle back (the paper keeps the clusters in registers too).
template <class Warp>
RF_HDI LanesOf<Warp, uint32_t> nearest_neighbours(Warp& warp, const LanesOf<Warp, Box3f>& box, uint32_t count,
                                                  uint32_t radius) {
    LanesOf<Warp, uint64_t> best;
    warp.for_each_lane([&](uint32_t lane) { best[lane] = ploc::kNoNeighbour; });
    const uint32_t farthest = radius < count - 1 ? radius : count - 1;
    for (uint32_t d = 1; d <= farthest; ++d) {
        const LanesOf<Warp, Box3f> right =
            warp.shuffle(box, [&](uint32_t lane) { return lane + d < kWarpLanes ? lane + d : lane; });
        LanesOf<Warp, float> area;
        warp.for_each_lane([&](uint32_t lane) {
            area[lane] = 0.0f;
            if (lane + d >= count) return;
            area[lane] = ploc::merged_area(box[lane], right[lane]);
            const uint64_t key = ploc::neighbour_key(area[lane], lane, lane + d);
            best[lane] = key < best[lane] ? key : best[lane];
        });
        const LanesOf<Warp, float> left_area = warp.shuffle(area, [&](uint32_t lane) { return lane >= d ? lane - d : lane; });
        warp.for_each_lane([&](uint32_t lane) {
            if (lane < d || lane >= count) return;
            const uint64_t key = ploc::neighbour_key(left_area[lane], lane, lane - d);
            best[lane] = key < best[lane] ? key : best[lane];
        });
    }
    LanesOf<Warp, uint32_t> neighbour;
    warp.for_each_lane(
        [&](uint32_t lane) { neighbour[lane] = lane < count ? ploc::neighbour_from_key(lane, best[lane]) : lane; });
    return neighbour;
}

// One PLOC step over the warp's `count` clusters (ref, box in lanes 0 ..
// count - 1): mutual nearest neighbours l < m become a new node (children
// in lane order, so the left one is the earlier in the Morton order) in
// lane l, numbered from a counter in lane order; the clusters left are
// compacted to the front in lane order. Returns the merges (>= 1).
template <class Warp, class Memory>
RF_HDI uint32_t merge_step(Warp& warp, Memory& memory, LanesOf<Warp, uint32_t>& ref, LanesOf<Warp, Box3f>& box,
                           uint32_t count, uint32_t radius, uint32_t* node_counter) {
    const LanesOf<Warp, uint32_t> neighbour = nearest_neighbours(warp, box, count, radius);
    const LanesOf<Warp, uint32_t> neighbours_neighbour =
        warp.shuffle(neighbour, [&](uint32_t lane) { return neighbour[lane]; });
    const auto mutual = [&](uint32_t lane) { return lane < count && neighbours_neighbour[lane] == lane; };
    const uint32_t merging = warp.ballot([&](uint32_t lane) { return mutual(lane) && lane < neighbour[lane]; });
    const uint32_t staying =
        warp.ballot([&](uint32_t lane) { return lane < count && (!mutual(lane) || lane < neighbour[lane]); });
    const uint32_t merges = static_cast<uint32_t>(hlbvh2::popcount(merging));
    if (merges == 0) return 0;  // impossible (the closest pair is mutual); the caller stops
    const uint32_t first_node = warp.add_once(node_counter, merges);
    const LanesOf<Warp, uint32_t> partner_ref = warp.shuffle(ref, [&](uint32_t lane) { return neighbour[lane]; });
    const LanesOf<Warp, Box3f> partner_box = warp.shuffle(box, [&](uint32_t lane) { return neighbour[lane]; });
    warp.for_each_lane([&](uint32_t lane) {
        if (((merging >> lane) & 1u) == 0) return;
        const uint32_t node = first_node + static_cast<uint32_t>(hlbvh2::popcount(merging & lanes_below(lane)));
        const Box3f merged = karras::box_union(box[lane], partner_box[lane]);
        memory.write_node(node, ref[lane], partner_ref[lane], merged);
        ref[lane] = node;
        box[lane] = merged;
    });
    LanesOf<Warp, uint32_t> source;  // lane i takes the i-th cluster that stays
    warp.for_each_lane([&](uint32_t lane) { source[lane] = nth_set_lane(staying, lane, lane); });
    ref = warp.shuffle(ref, [&](uint32_t lane) { return source[lane]; });
    box = warp.shuffle(box, [&](uint32_t lane) { return source[lane]; });
    return merges;
}

// The lanes that load the clusters of a child range at `first` (lanes from
// `lane_offset` on, its first min(slots, kMergeThreshold) slots); returns
// how many it has (the non-empty slots, at the front).
template <class Warp, class Memory>
RF_HDI uint32_t load_child(Warp& warp, Memory& memory, LanesOf<Warp, uint32_t>& ref, uint32_t first, uint32_t slots,
                           uint32_t lane_offset) {
    const uint32_t loaded = slots < kMergeThreshold ? slots : kMergeThreshold;
    warp.for_each_lane([&](uint32_t lane) {
        if (lane < lane_offset) return;
        ref[lane] = lane - lane_offset < loaded ? memory.load_ref(first + (lane - lane_offset)) : kNoCluster;
    });
    return static_cast<uint32_t>(
        hlbvh2::popcount(warp.ballot([&](uint32_t lane) { return lane >= lane_offset && ref[lane] != kNoCluster; })));
}

// The warp's work on range [left, right] with its right child from `split`
// (the per-range PLOC merge): the children's clusters into lanes, PLOC steps
// until at most kMergeThreshold are left (one for the root), and back into
// the range's slots, the slots read emptied behind them. Returns the
// clusters left (0 only if a step failed to merge).
template <class Warp, class Memory>
RF_HDI uint32_t process_range(Warp& warp, Memory& memory, uint32_t left, uint32_t split, uint32_t right, bool root,
                              uint32_t radius, uint32_t* node_counter) {
    LanesOf<Warp, uint32_t> ref;
    const uint32_t from_left = load_child(warp, memory, ref, left, split - left, 0);
    const uint32_t loaded = from_left + load_child(warp, memory, ref, split, right + 1 - split, from_left);
    LanesOf<Warp, Box3f> box;
    warp.for_each_lane([&](uint32_t lane) {
        if (lane < loaded) box[lane] = memory.box(ref[lane]);
    });
    const uint32_t target = root ? 1u : kMergeThreshold;
    uint32_t count = loaded;
    while (count > target) {
        const uint32_t merges = merge_step(warp, memory, ref, box, count, radius, node_counter);
        if (merges == 0) return 0;
        count -= merges;
    }
    warp.for_each_lane([&](uint32_t lane) {
        if (lane < loaded) memory.store_ref(left + lane, lane < count ? ref[lane] : kNoCluster);
    });
    memory.publish();
    warp.sync();
    return count;
}

// The build's shared state.
struct Build {
    const uint64_t* keys;      // n sorted 63-bit Morton codes
    uint32_t n;                // >= 2
    uint32_t* boundary_slots;  // n - 1, kNoRangeEnd at the start
    uint32_t* node_counter;    // 0 at the start; n - 1 at the end
    uint32_t radius;           // clamp_radius'd
};

// One round of the warp's loop (the paper's outer loop): every climbing lane
// goes one step up; then the warp processes, lowest lane first, the ranges
// of the lanes whose range spans more than kMergeThreshold leaves or is the
// root, and lanes at the root stop. Returns false when no lane of the warp
// climbs any more; and sets *failed when a range could not be merged.
template <class Warp, class Memory>
RF_HDI bool warp_round(Warp& warp, Memory& memory, const Build& build, LanesOf<Warp, Range>& range, bool* failed) {
    if (warp.ballot([&](uint32_t lane) { return range[lane].active; }) == 0) return false;
    warp.for_each_lane([&](uint32_t lane) {
        Range& r = range[lane];
        if (r.active) r.active = climb(build.keys, build.n, build.boundary_slots, memory, r);
    });
    uint32_t pending = warp.ballot([&](uint32_t lane) {
        const Range& r = range[lane];
        return r.active && (range_size(r) > kMergeThreshold || range_size(r) == build.n);
    });
    while (pending != 0) {
        const uint32_t owner = nth_set_lane(pending, 0, 0);
        const Range r = warp.read_lane(range, owner);
        const bool root = range_size(r) == build.n;
        if (process_range(warp, memory, r.left, r.split, r.right, root, build.radius, build.node_counter) == 0) {
            *failed = true;
        }
        pending &= pending - 1;
    }
    warp.for_each_lane([&](uint32_t lane) {
        Range& r = range[lane];
        if (r.active && range_size(r) == build.n) r.active = false;
    });
    return true;
}

// ---- The CPU's warp: 32 lanes in a loop ----

template <class T>
struct LaneArray {
    T value[kWarpLanes];
    RF_HDI T& operator[](uint32_t lane) { return value[lane]; }
    RF_HDI const T& operator[](uint32_t lane) const { return value[lane]; }
};

// Host only. Runs a warp's lanes one after the other, in lane order; the
// lanes of a shuffle read the values as they were before it, as on the device.
struct SimulatedWarp {
    template <class T>
    using Lanes = LaneArray<T>;

    template <class F>
    void for_each_lane(F&& f) {
        for (uint32_t lane = 0; lane < kWarpLanes; ++lane) f(lane);
    }
    template <class F>
    uint32_t ballot(F&& predicate) {
        uint32_t mask = 0;
        for (uint32_t lane = 0; lane < kWarpLanes; ++lane) mask |= predicate(lane) ? 1u << lane : 0u;
        return mask;
    }
    // `source(lane)` in 0 .. kWarpLanes - 1.
    template <class T, class F>
    Lanes<T> shuffle(const Lanes<T>& values, F&& source) {
        Lanes<T> out;
        for (uint32_t lane = 0; lane < kWarpLanes; ++lane) out[lane] = values[source(lane)];
        return out;
    }
    template <class T>
    T read_lane(const Lanes<T>& values, uint32_t lane) {
        return values[lane];
    }
    // One atomic add for the warp; every lane gets the value before it.
    uint32_t add_once(uint32_t* counter, uint32_t value) {
        return __atomic_fetch_add(counter, value, __ATOMIC_RELAXED);
    }
    void sync() {}
};

}  // namespace rf::hploc
