// Leaf finishing and canonical emission of GridBvh / GridBvhSplit (Garanzha
// 2014, dissertation ch. 4: §4.3 "leaves are split when they hold more than
// 4 references", and the bottom-up boxes after EmitHierarchy, Algorithm 4.1),
// as per-thread steps shared by the CPU builder (grid_bvh.cpp) and the CUDA
// builder (backend/cuda/grid_bvh_build.cu), so both give the same BVH:
//  - one leaf, one thread: its reference indices sorted, the references
//    gathered, parts of one triangle merged (union box), then kept as one
//    leaf or split by a small binned SAH over the reference centroids (8
//    bins, SAH termination with C_trav / C_int, median splits near the depth
//    limit or when the centroids coincide), built iteratively with an
//    explicit stack that allocates node pairs in the order of the CPU's
//    recursion (node, its pair, the left subtree, then the right one);
//  - the emission over the grid hierarchy, one thread per hierarchy node:
//    subtree sizes and boxes bottom-up per tree level, positions top-down,
//    then the copy into rf::Bvh's depth-first layout.
// Products and sums that feed a comparison or an output are rounded once
// each (core/rounded_arithmetic.h: nvcc would fuse them into FMAs); box
// growth uses std::min / std::max semantics (gridbvh::vmin / vmax).
#pragma once

#include <cstdint>

#include "accel/bvh/builders/grid_bvh_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"

namespace rf::gridbvh {

// References (before merging) one device thread can finish in its local
// arrays (the references, a partition buffer, the build stack: about 5 KB).
// A leaf with more (a crowded Grid0 cell, or the depth limit) makes the
// device hand the whole finishing and emission to the host.
inline constexpr uint32_t kDeviceFinishRefs = 64;
inline constexpr int kFinishBins = 8;

// What the finishing needs from BuildOptions.
struct FinishOptions {
    uint32_t max_leaf_size;  // >= 1
    float traversal_cost;
    float intersection_cost;
};

// A finished leaf of the grid hierarchy: its box, the nodes of its subtree
// (1: a single leaf node) and its triangles.
struct LeafSummary {
    Box3f box;
    uint32_t node_count;
    uint32_t prim_count;
};

// One entry of the iterative local build: build `node` over refs[begin, begin + count).
struct LocalTask {
    uint32_t node;
    uint32_t begin;
    uint32_t count;
    int depth;
};

RF_HDI Box3f box_union(const Box3f& a, const Box3f& b) { return {vmin(a.lo, b.lo), vmax(a.hi, b.hi)}; }

// Box3f::surface_area with each product and sum rounded once: 2 (xy + yz + zx).
RF_HDI float surface_area_rn(const Box3f& b) {
    if (b.is_empty()) return 0.0f;
    const Vec3f e = b.extent();
    return mul_rn(2.0f, add_rn(add_rn(mul_rn(e.x, e.y), mul_rn(e.y, e.z)), mul_rn(e.z, e.x)));
}

// Whether splitting is not cheaper by the SAH than one leaf of `count`:
// C_trav A + C_int cost >= C_int A count.
RF_HDI bool leaf_is_cheaper(const FinishOptions& o, float area, float split_cost, uint32_t count) {
    return add_rn(mul_rn(o.traversal_cost, area), mul_rn(o.intersection_cost, split_cost)) >=
           mul_rn(mul_rn(o.intersection_cost, area), float(count));
}

RF_HDI void bounds_and_centroids(const GridRef* refs, uint32_t count, Box3f& bounds, Box3f& centroids) {
    bounds = Box3f{};
    centroids = Box3f{};
    for (uint32_t i = 0; i < count; ++i) {
        bounds = box_union(bounds, refs[i].bounds());
        const Vec3f c = refs[i].centroid();
        centroids = {vmin(centroids.lo, c), vmax(centroids.hi, c)};
    }
}

// Ascending insertion sort (reference indices of a leaf; usually sorted already).
RF_HDI void insertion_sort(uint32_t* v, uint32_t count) {
    for (uint32_t i = 1; i < count; ++i) {
        const uint32_t x = v[i];
        uint32_t j = i;
        for (; j > 0 && v[j - 1] > x; --j) v[j] = v[j - 1];
        v[j] = x;
    }
}

// Parts of one triangle in one leaf become one reference (union box): a
// stable sort by triangle, then runs merged in order. Returns the new count.
RF_HDI uint32_t merge_parts(GridRef* refs, uint32_t count) {
    for (uint32_t i = 1; i < count; ++i) {
        const GridRef r = refs[i];
        uint32_t j = i;
        for (; j > 0 && refs[j - 1].prim > r.prim; --j) refs[j] = refs[j - 1];
        refs[j] = r;
    }
    uint32_t out = 0;
    for (uint32_t i = 0; i < count; ++i) {
        if (out > 0 && refs[out - 1].prim == refs[i].prim) {
            refs[out - 1].lo = vmin(refs[out - 1].lo, refs[i].lo);
            refs[out - 1].hi = vmax(refs[out - 1].hi, refs[i].hi);
        } else {
            refs[out++] = refs[i];
        }
    }
    return out;
}

// The bin of centroid coordinate c: floor((c - lo) * scale) in [0, kFinishBins).
// Clamped as a float, so an infinite or NaN product has one answer on both compilers.
RF_HDI int finish_bin(float c, float lo, float scale) {
    const float x = (c - lo) * scale;
    return x >= float(kFinishBins - 1) ? kFinishBins - 1 : (x > 0.0f ? int(x) : 0);
}

RF_HDI float finish_bin_scale(float extent) { return float(kFinishBins) * (1.0f - 0x1p-20f) / extent; }

// Binned SAH over the references' centroids (8 bins per axis, the first
// strictly cheapest plane in axis-then-plane order); partitions refs stably
// (`scratch`: room for `count` references) and returns the left count, or 0
// when no plane separates them. `cost`: SA(left) nL + SA(right) nR.
RF_HDI uint32_t split_binned(GridRef* refs, uint32_t count, const Box3f& centroids, float& cost, GridRef* scratch) {
    const Vec3f extent = centroids.extent();
    int best_axis = -1, best_bin = 0;
    float best_cost = 0.0f;
    for (int a = 0; a < 3; ++a) {
        if (!(extent[a] > 0.0f)) continue;
        const float scale = finish_bin_scale(extent[a]);
        Box3f bin_box[kFinishBins];
        uint32_t bin_count[kFinishBins];
        for (int b = 0; b < kFinishBins; ++b) {
            bin_box[b] = Box3f{};
            bin_count[b] = 0;
        }
        for (uint32_t i = 0; i < count; ++i) {
            const int b = finish_bin(refs[i].centroid()[a], centroids.lo[a], scale);
            bin_box[b] = box_union(bin_box[b], refs[i].bounds());
            ++bin_count[b];
        }
        float right_area[kFinishBins];
        uint32_t right_count[kFinishBins];
        Box3f acc;
        uint32_t n = 0;
        for (int i = kFinishBins - 1; i > 0; --i) {
            acc = box_union(acc, bin_box[i]);
            n += bin_count[i];
            right_area[i] = surface_area_rn(acc);
            right_count[i] = n;
        }
        acc = Box3f{};
        n = 0;
        for (int i = 1; i < kFinishBins; ++i) {
            acc = box_union(acc, bin_box[i - 1]);
            n += bin_count[i - 1];
            if (n == 0 || right_count[i] == 0) continue;
            const float c = add_rn(mul_rn(surface_area_rn(acc), float(n)), mul_rn(right_area[i], float(right_count[i])));
            if (best_axis < 0 || c < best_cost) {
                best_axis = a;
                best_bin = i;
                best_cost = c;
            }
        }
    }
    if (best_axis < 0) return 0;
    cost = best_cost;
    // Stable partition: the left ones compact in place, the right ones wait in scratch.
    const float scale = finish_bin_scale(extent[best_axis]);
    uint32_t left = 0, right = 0;
    for (uint32_t i = 0; i < count; ++i) {
        if (finish_bin(refs[i].centroid()[best_axis], centroids.lo[best_axis], scale) < best_bin) {
            refs[left++] = refs[i];
        } else {
            scratch[right++] = refs[i];
        }
    }
    for (uint32_t i = 0; i < right; ++i) refs[left + i] = scratch[i];
    return left;
}

// The median order on `axis`: by the centroid coordinate (lo + hi, unhalved),
// ties by triangle index (unique after merging), so the order is total and
// every sort gives the same sequence. Coordinates are finite (Scene::finalize).
RF_HDI bool median_before(const GridRef& a, const GridRef& b, int axis) {
    const float ca = a.lo[axis] + a.hi[axis], cb = b.lo[axis] + b.hi[axis];
    return ca < cb || (ca == cb && a.prim < b.prim);
}

// The sort of the median split on one thread (leaves of at most
// kDeviceFinishRefs). The CPU sorts larger ranges with std::sort and
// median_before: the same result, the order being total.
struct InsertionSortOnAxis {
    RF_HDI void operator()(GridRef* refs, uint32_t count, int axis) const {
        for (uint32_t i = 1; i < count; ++i) {
            const GridRef r = refs[i];
            uint32_t j = i;
            for (; j > 0 && median_before(r, refs[j - 1], axis); --j) refs[j] = refs[j - 1];
            refs[j] = r;
        }
    }
};

// Object median on the widest centroid axis (the whole range sorted by
// median_before); halves by position when all centroids coincide.
template <class SortOnAxis>
RF_HDI uint32_t split_median(GridRef* refs, uint32_t count, const Box3f& centroids, const SortOnAxis& sort) {
    const Vec3f extent = centroids.extent();
    if (extent.x > 0.0f || extent.y > 0.0f || extent.z > 0.0f) sort(refs, count, centroids.largest_axis());
    return count / 2;
}

// Whether `count` (<= max_leaf_size) references stay one leaf: unless a
// binned split is cheaper by the SAH. Partitions the references as the
// split would (the kept leaf lists them in that order).
RF_HDI bool keep_as_leaf(GridRef* refs, uint32_t count, const FinishOptions& o, GridRef* scratch) {
    if (count <= 1) return true;
    Box3f bounds, centroids;
    bounds_and_centroids(refs, count, bounds, centroids);
    float cost = 0.0f;
    const uint32_t mid = split_binned(refs, count, centroids, cost, scratch);
    return mid == 0 || mid == count || leaf_is_cheaper(o, surface_area_rn(bounds), cost, count);
}

// One node of the local build over refs[0, count) at tree depth `depth`.
struct LocalSplit {
    Box3f bounds;
    uint32_t mid;  // left count of an inner node
    bool leaf;
};

// Leaf at <= max_leaf_size references when no binned split is cheaper;
// otherwise the binned split, or the median when the binned one separates
// nothing or would leave the larger side too many halvings before kBvhMaxDepth.
template <class SortOnAxis>
RF_HDI LocalSplit split_local_node(GridRef* refs, uint32_t count, int depth, const FinishOptions& o, GridRef* scratch,
                                   const SortOnAxis& sort) {
    LocalSplit s;
    Box3f centroids;
    bounds_and_centroids(refs, count, s.bounds, centroids);
    float cost = 0.0f;
    uint32_t mid = count > 1 ? split_binned(refs, count, centroids, cost, scratch) : 0;
    const bool no_split = mid == 0 || mid == count;
    if (count <= o.max_leaf_size && (no_split || leaf_is_cheaper(o, surface_area_rn(s.bounds), cost, count))) {
        s.mid = 0;
        s.leaf = true;
        return s;
    }
    const uint32_t larger = mid > count - mid ? mid : count - mid;
    if (no_split || depth + 1 + median_levels(larger, o.max_leaf_size) > kBvhMaxDepth) {
        mid = split_median(refs, count, centroids, sort);
    }
    s.mid = mid;
    s.leaf = false;
    return s;
}

// The local tree over refs[0, count) in canonical relative layout: node 0
// the root, an inner node's `first` its local left child (siblings
// adjacent), a leaf's `first` its slot in `prims`. Iterative: the stack
// (room for `count` entries: it never holds more than the depth + 1) pops
// the left child first, so pairs are allocated in the recursion's order.
// Returns the node count.
template <class SortOnAxis>
RF_HDI uint32_t build_local_tree(GridRef* refs, uint32_t count, int depth, const FinishOptions& o, GridRef* scratch,
                                 LocalTask* stack, BvhNode* nodes, uint32_t* prims, const SortOnAxis& sort) {
    uint32_t top = 0, node_count = 1, prim_count = 0;
    stack[top++] = LocalTask{0, 0, count, depth};
    while (top > 0) {
        const LocalTask t = stack[--top];
        const LocalSplit s = split_local_node(refs + t.begin, t.count, t.depth, o, scratch + t.begin, sort);
        BvhNode& node = nodes[t.node];
        node.bounds = s.bounds;
        if (s.leaf) {
            node.first = prim_count;
            node.count = t.count;
            for (uint32_t i = 0; i < t.count; ++i) prims[prim_count++] = refs[t.begin + i].prim;
            continue;
        }
        const uint32_t pair = node_count;
        node_count += 2;
        node.first = pair;
        node.count = 0;
        stack[top++] = LocalTask{pair + 1, t.begin + s.mid, t.count - s.mid, t.depth + 1};
        stack[top++] = LocalTask{pair, t.begin, s.mid, t.depth + 1};
    }
    return node_count;
}

// A leaf kept as one node: its box and its triangles in reference order.
RF_HDI LeafSummary single_leaf(const GridRef* refs, uint32_t count, uint32_t* prims) {
    LeafSummary s;
    s.box = Box3f{};
    for (uint32_t k = 0; k < count; ++k) {
        s.box = box_union(s.box, refs[k].bounds());
        prims[k] = refs[k].prim;
    }
    s.node_count = 1;
    s.prim_count = count;
    return s;
}

// Finishes a leaf over its gathered references refs[0, count): merging,
// then one leaf node or a local tree. Writes the triangles to prims (room
// for `count`) and, for a tree (node_count > 1), its nodes to nodes (room
// for 2 count - 1); scratch and stack hold `count` entries.
template <class SortOnAxis>
RF_HDI LeafSummary finish_gathered_leaf(GridRef* refs, uint32_t count, int depth, const FinishOptions& o,
                                        GridRef* scratch, LocalTask* stack, BvhNode* nodes, uint32_t* prims,
                                        const SortOnAxis& sort) {
    count = merge_parts(refs, count);
    if (count <= o.max_leaf_size && keep_as_leaf(refs, count, o, scratch)) return single_leaf(refs, count, prims);
    LeafSummary s;
    s.prim_count = count;
    s.node_count = build_local_tree(refs, count, depth, o, scratch, stack, nodes, prims, sort);
    s.box = nodes[0].bounds;
    return s;
}

// One device thread's leaf: `count` (<= kDeviceFinishRefs) reference
// indices of the leaf in any order (sorted here, as the CPU sorts them),
// gathered from `refs` into local arrays and finished.
RF_HDI LeafSummary finish_small_leaf(const GridRef* refs, const uint32_t* leaf_refs, uint32_t count, int depth,
                                     const FinishOptions& o, BvhNode* nodes, uint32_t* prims) {
    uint32_t ids[kDeviceFinishRefs];
    GridRef local[kDeviceFinishRefs];
    GridRef scratch[kDeviceFinishRefs];
    LocalTask stack[kDeviceFinishRefs];
    for (uint32_t i = 0; i < count; ++i) ids[i] = leaf_refs[i];
    insertion_sort(ids, count);
    for (uint32_t i = 0; i < count; ++i) local[i] = refs[ids[i]];
    return finish_gathered_leaf(local, count, depth, o, scratch, stack, nodes, prims, InsertionSortOnAxis{});
}

// ---- emission: one thread per hierarchy node ----

// Per hierarchy node: nodes and triangles of its subtree and its box.
struct SubtreeSize {
    uint32_t nodes;
    uint32_t prims;
};

// Bottom-up (deepest level first): node h from its leaf or its children.
RF_HDI void emit_size_and_box(uint32_t h, const uint32_t* hnodes, const LeafSummary* leaves, SubtreeSize* size,
                              Box3f* box) {
    const uint32_t first = hnodes[h];
    if (first & kLeafBit) {
        const LeafSummary& leaf = leaves[first & ~kLeafBit];
        size[h] = SubtreeSize{leaf.node_count, leaf.prim_count};
        box[h] = leaf.box;
    } else {
        size[h] = SubtreeSize{1 + size[first].nodes + size[first + 1].nodes, size[first].prims + size[first + 1].prims};
        box[h] = box_union(box[first], box[first + 1]);
    }
}

// Where a hierarchy node lands in the depth-first layout: its own slot, the
// first slot of its descendants (its children's pair) and its first triangle.
struct EmitPosition {
    uint32_t pos;
    uint32_t desc;
    uint32_t prim_base;
};

RF_HDI EmitPosition root_position() { return EmitPosition{0, 1, 0}; }

// Top-down (root level first): an inner node h places its two children.
RF_HDI void emit_positions(uint32_t h, const uint32_t* hnodes, const SubtreeSize* size, EmitPosition* at) {
    const uint32_t first = hnodes[h];
    if (first & kLeafBit) return;
    const uint32_t left = first, right = first + 1;
    const EmitPosition p = at[h];
    at[left] = EmitPosition{p.desc, p.desc + 2, p.prim_base};
    at[right] = EmitPosition{p.desc + 1, p.desc + 2 + size[left].nodes - 1, p.prim_base + size[left].prims};
}

// The copy of an inner hierarchy node.
RF_HDI void emit_inner_node(const Box3f& box, const EmitPosition& at, BvhNode* out_nodes) {
    BvhNode& out = out_nodes[at.pos];
    out.bounds = box;
    out.first = at.desc;
    out.count = 0;
}

// The copy of a finished leaf: its single node, or its local tree (local
// node j >= 1 at desc + j - 1), and its triangles from `prims`.
RF_HDI void emit_leaf(const LeafSummary& leaf, const BvhNode* local_nodes, const uint32_t* prims, const EmitPosition& at,
                      BvhNode* out_nodes, uint32_t* out_prims) {
    if (leaf.node_count == 1) {
        BvhNode& out = out_nodes[at.pos];
        out.bounds = leaf.box;
        out.first = at.prim_base;
        out.count = leaf.prim_count;
    } else {
        for (uint32_t j = 0; j < leaf.node_count; ++j) {
            BvhNode node = local_nodes[j];
            node.first = node.is_leaf() ? at.prim_base + node.first : at.desc + node.first - 1;
            out_nodes[j == 0 ? at.pos : at.desc + j - 1] = node;
        }
    }
    for (uint32_t k = 0; k < leaf.prim_count; ++k) out_prims[at.prim_base + k] = prims[k];
}

}  // namespace rf::gridbvh
