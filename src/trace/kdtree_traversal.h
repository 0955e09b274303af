// Single-ray kd-tree traversals of Zlatuška 2009 (sec. 4.3.1.2),
// written once for the host and the CUDA backend on a plain view struct:
//  - Stack:      the classic recursive (near child first) traversal with a
//                full stack of far children;
//  - ShortStack: a ring buffer of the last few far children (Horn et al.
//                2007); when it runs dry, a restart;
//  - Restart:    kd-restart (Foley and Sugerman 2005): no stack at all, every
//                leaf is followed by a new descent from the root;
//  - Pushdown:   kd-restart that restarts from the deepest node known to
//                hold the rest of the ray's segment (Horn et al. 2007).
//
// Restarting without an epsilon. Foley and Sugerman restart with tmin moved to
// the finished leaf's tmax and pick children by comparing distances; leaves
// that share one distance (zero-thickness cells from planar geometry or
// perfect splits, rays through cell corners) are then either revisited
// forever or skipped (the flaw Zlatuška 2009 notes). Here the descent that follows a
// finished leaf is told where to go by a trail, one bit per depth ("the near
// child of the branch at this depth is finished": the role tmin plays in
// kd-restart, but exact). The next leaf is the far child of the deepest branch
// still pending, exactly the entry a full stack would pop, so all four
// traversals visit the same leaves in the same order and each restart moves
// the trail strictly forward: no loops, no skips.
//
// Distances to split planes are rounded outwards by 2 gamma(3) (as the BVH's
// box test, after Ize 2013) so that a cell the ray touches is never culled by
// rounding. Rays lying in a split plane (0 * inf) visit both children with the
// same interval. A hit counts wherever it lies in [ray.tmin, ray.tmax]; the
// traversal stops after a leaf whose interval holds the closest hit so far.
#pragma once

#include <cstdint>

#include "accel/kdtree/kdtree.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/triangle_intersect.h"

namespace rf {

// A kd-tree as the traversal sees it; node_count == 0 is the empty tree.
struct KdTreeView {
    const KdNode* nodes = nullptr;
    const uint32_t* prim_indices = nullptr;
    const Triangle* triangles = nullptr;
    uint32_t node_count = 0;
    Box3f bounds;              // the root cell
    int short_stack_size = 4;  // ring entries of the ShortStack traversal (1 .. kKdMaxShortStack)
};

inline constexpr int kKdMaxShortStack = 64;

// Work done by one traversal (filled by the counting variants, accumulated).
struct KdTraversalCounters {
    uint32_t nodes_visited = 0;  // inner nodes and leaves, re-descents included
    uint32_t prims_tested = 0;   // triangle tests
    uint32_t restarts = 0;       // descents from the root (or pushdown node) after a leaf
};

namespace kd_detail {

// 1 -/+ 2 gamma(3), gamma(n) = n u / (1 - n u), u = 2^-24: a distance
// computed as (plane - org) * (1 / dir) times these brackets the exact one.
inline constexpr float kGamma3 = (3.0f * 0x1p-24f) / (1.0f - 3.0f * 0x1p-24f);
inline constexpr float kScaleUp = 1.0f + 2.0f * kGamma3;
inline constexpr float kScaleDown = 1.0f - 2.0f * kGamma3;

RF_HDI float round_down(float t) { return t >= 0.0f ? t * kScaleDown : t * kScaleUp; }
RF_HDI float round_up(float t) { return t >= 0.0f ? t * kScaleUp : t * kScaleDown; }
RF_HDI float min_f(float a, float b) { return a < b ? a : b; }
RF_HDI float max_f(float a, float b) { return a > b ? a : b; }

RF_HDI int highest_bit(uint64_t x) {
#if defined(__CUDA_ARCH__)
    return 63 - __clzll(static_cast<long long>(x));
#else
    return 63 - __builtin_clzll(x);
#endif
}

// The part of [ray.tmin, ray.tmax] inside the root cell, rounded outwards;
// false when the ray misses the cell.
RF_HDI bool clip_to_root(const Box3f& box, const Ray& ray, const float inv[3], float& lo, float& hi) {
    lo = round_down(ray.tmin);
    hi = round_up(ray.tmax);
    for (int k = 0; k < 3; ++k) {
        const float o = ray.org[k];
        if (!(inv[k] >= -kInfinity && inv[k] <= kInfinity)) {
            // Parallel to the slab (or practically so): inside it or never.
            if (o < box.lo[k] || o > box.hi[k]) return false;
            continue;
        }
        float t0 = (box.lo[k] - o) * inv[k];
        float t1 = (box.hi[k] - o) * inv[k];
        if (t0 > t1) {
            const float swap = t0; t0 = t1; t1 = swap;
        }
        lo = max_f(lo, round_down(t0));
        hi = min_f(hi, round_up(t1));
    }
    return lo <= hi;
}

struct StackEntry {
    uint32_t node;  // the far child
    int depth;      // depth of the branching node
    float lo, hi;   // the far child's interval
};

// The one loop behind every traversal: closest hit (kAnyHit = false) or first
// hit (kAnyHit = true), instrumented when kCount.
template <KdTraversal kMode, bool kAnyHit, bool kCount>
RF_HDI Hit traverse(const KdTreeView& tree, const Ray& ray, KdTraversalCounters* counters) {
    Hit hit;
    if (tree.node_count == 0) return hit;
    const float inv[3] = {1.0f / ray.dir.x, 1.0f / ray.dir.y, 1.0f / ray.dir.z};
    float lo, hi;
    if (!clip_to_root(tree.bounds, ray, inv, lo, hi)) return hit;
    const WatertightRay tri_ray = WatertightRay::make(ray);
    float best = ray.tmax;

    constexpr bool kHasStack = kMode == KdTraversal::Stack || kMode == KdTraversal::ShortStack;
    constexpr int kStackSlots = kMode == KdTraversal::Stack ? kKdMaxDepth
                                : kMode == KdTraversal::ShortStack ? kKdMaxShortStack : 1;
    StackEntry stack[kStackSlots];
    int capacity = kMode == KdTraversal::Stack ? kKdMaxDepth : 0;
    if constexpr (kMode == KdTraversal::ShortStack) {
        capacity = tree.short_stack_size < 1 ? 1 : (tree.short_stack_size > kKdMaxShortStack ? kKdMaxShortStack
                                                                                             : tree.short_stack_size);
    }
    int top = capacity - 1;  // ring: slot of the newest entry
    int count = 0;

    // Per depth: a branch whose far child is still to come; such a branch made
    // by a ray lying in the split plane; the near child is finished (trail).
    uint64_t pending = 0, in_plane = 0, trail = 0;

    uint32_t restart_node = 0;
    int restart_depth = 0;
    float restart_lo = lo, restart_hi = hi;

    uint32_t node_index = 0;
    int depth = 0;
    for (;;) {
        // Down to a leaf.
        KdNode node = tree.nodes[node_index];
        while (!node.is_leaf()) {
            if constexpr (kCount) ++counters->nodes_visited;
            const int axis = node.axis();
            const float t_split = (node.split() - ray.org[axis]) * inv[axis];
            // Near child: the side the ray comes from (by direction, so that a
            // ray moving away from the plane gets t_split < lo and stays near).
            const uint32_t first = node.first_child();
            const bool negative = inv[axis] < 0.0f;
            const uint32_t near_child = first + (negative ? 1u : 0u);
            const uint32_t far_child = first + (negative ? 0u : 1u);
            bool near_ok = true, far_ok = true, plane_ray = false;
            float near_hi = hi, far_lo = lo;
            if (t_split == t_split) {
                const float t_lo = round_down(t_split), t_hi = round_up(t_split);
                near_ok = lo <= t_hi;
                far_ok = t_lo <= hi;
                near_hi = min_f(t_hi, hi);
                far_lo = max_f(t_lo, lo);
            } else {
                plane_ray = true;  // 0 * inf: the ray lies in the plane, in both children
            }
            const uint64_t bit = uint64_t(1) << depth;
            if (near_ok && far_ok && (trail & bit) == 0) {
                pending |= bit;
                if (plane_ray) in_plane |= bit;
                if constexpr (kHasStack) {
                    top = top + 1 == capacity ? 0 : top + 1;  // a full ring forgets its oldest entry
                    stack[top] = StackEntry{far_child, depth, far_lo, hi};
                    if (count < capacity) ++count;
                }
                node_index = near_child;
                hi = near_hi;
            } else if (near_ok && !far_ok) {
                node_index = near_child;
                hi = near_hi;
            } else {
                // Far only, or the near child is finished (the trail says so).
                node_index = far_child;
                lo = far_lo;
            }
            ++depth;
            if constexpr (kMode == KdTraversal::Pushdown) {
                // No branch pending above: the rest of the segment lies in this child.
                if ((pending & ((bit << 1) - 1)) == 0) {
                    restart_node = node_index;
                    restart_depth = depth;
                    restart_lo = lo;
                    restart_hi = hi;
                }
            }
            node = tree.nodes[node_index];
        }

        // The leaf.
        if constexpr (kCount) ++counters->nodes_visited;
        const uint32_t end = node.prim_offset() + node.prim_count();
        for (uint32_t slot = node.prim_offset(); slot < end; ++slot) {
            const uint32_t prim = tree.prim_indices[slot];
            if constexpr (kCount) ++counters->prims_tested;
            TriangleHit candidate;
            if (intersect_triangle(tri_ray, tree.triangles[prim], ray.tmin, best, candidate)) {
                hit.t = candidate.t;
                hit.u = candidate.u;
                hit.v = candidate.v;
                hit.prim = prim;
                if constexpr (kAnyHit) return hit;
                best = candidate.t;
            }
        }

        // The closest hit lies within this leaf's interval: every branch still
        // pending starts behind it, except those of a ray in a split plane
        // (their far child overlaps the interval already traversed).
        if (hit.found() && best <= hi) pending &= in_plane;
        if (pending == 0) return hit;

        // Next: the far child of the deepest pending branch.
        const int branch = highest_bit(pending);
        const uint64_t above = (uint64_t(1) << branch) - 1;
        trail = (trail & above) | (above + 1);
        pending &= above;
        in_plane &= above;
        bool popped = false;
        if constexpr (kHasStack) {
            while (count > 0 && stack[top].depth > branch) {  // branches cut off by a hit
                top = top == 0 ? capacity - 1 : top - 1;
                --count;
            }
            if (count > 0 && stack[top].depth == branch) {
                const StackEntry e = stack[top];
                top = top == 0 ? capacity - 1 : top - 1;
                --count;
                node_index = e.node;
                depth = branch + 1;
                lo = e.lo;
                hi = e.hi;
                popped = true;
            }
        }
        if (!popped) {
            // The entry is not at hand: descend again, the trail leads to it.
            if constexpr (kCount) ++counters->restarts;
            count = 0;
            node_index = restart_node;
            depth = restart_depth;
            lo = restart_lo;
            hi = restart_hi;
        }
    }
}

}  // namespace kd_detail

// Closest hit with t in [ray.tmin, ray.tmax]; prim indexes tree.triangles.
template <KdTraversal kMode>
RF_HDI Hit kdtree_intersect(const KdTreeView& tree, const Ray& ray) {
    return kd_detail::traverse<kMode, false, false>(tree, ray, nullptr);
}

// True when any triangle is hit with t in [ray.tmin, ray.tmax].
template <KdTraversal kMode>
RF_HDI bool kdtree_occluded(const KdTreeView& tree, const Ray& ray) {
    return kd_detail::traverse<kMode, true, false>(tree, ray, nullptr).found();
}

// Counting variants, for traversal statistics (counters are accumulated).
template <KdTraversal kMode>
RF_HDI Hit kdtree_intersect_counted(const KdTreeView& tree, const Ray& ray, KdTraversalCounters& counters) {
    return kd_detail::traverse<kMode, false, true>(tree, ray, &counters);
}
template <KdTraversal kMode>
RF_HDI bool kdtree_occluded_counted(const KdTreeView& tree, const Ray& ray, KdTraversalCounters& counters) {
    return kd_detail::traverse<kMode, true, true>(tree, ray, &counters).found();
}

}  // namespace rf
