// Leaf refinement before the CWBVH collapse (Ylitie, Karras and Laine 2017,
// section 3 starts from one triangle per leaf), one thread per canonical
// node: the device's version of cwbvh_layout.cpp's refine step, giving the
// same refined tree up to node numbering (which the collapse and the
// emission never see: they follow links, children left to right).
//
// Numbering: canonical node i keeps index i (siblings stay adjacent); a
// canonical leaf of c > 1 triangles also owns 2 (c - 1) extra nodes from
// n + extra_base on (extra_base: an exclusive scan of refined_extra over the
// canonical nodes), where its median-split subtree is laid out pair by pair.
// The same slots of a scratch array hold its references while it splits.
//
// A leaf's references are split at the median of their centroids along the
// longest axis of the centroid bounds, the lower half by (centroid, triangle
// index): a strict order, so the halves are the same sets whatever
// selection algorithm finds them (the CPU uses nth_element, a thread an
// insertion sort), and boxes are unions (order-free). Centroids are formed
// without contraction (mul_rn/add_rn) to match the CPU bit for bit.
#pragma once

#include <cstdint>

#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cwbvh {

struct RefineRef {
    Box3f box;  // triangle bounds clipped to the leaf's box
    Vec3f centroid;
    uint32_t prim;
};

// Extra refined nodes of canonical node `node` (the scan's input).
RF_HDI uint32_t refined_extra(const BvhNode& node) {
    return node.is_leaf() && node.count > 1 ? 2u * (node.count - 1u) : 0u;
}

RF_HDI bool ref_before(const RefineRef& a, const RefineRef& b, int axis) {
    const float ka = a.centroid[axis], kb = b.centroid[axis];
    return ka < kb || (ka == kb && a.prim < b.prim);
}

// Refined node(s) of canonical node i (n canonical nodes). Triangle counts
// of canonical inner nodes are left at 0 (the DP's walk sums them).
RF_HDI void refine_node(const BvhNode* canonical, uint32_t n, const uint32_t* prim_indices,
                        const Triangle* triangles, uint32_t i, uint32_t extra_base, RefineRef* scratch,
                        RefinedNode* out) {
    const BvhNode& node = canonical[i];
    RefinedNode r{};
    if (!node.is_leaf()) {
        r.box = node.bounds;
        r.left = node.first;
        out[i] = r;
        return;
    }
    if (node.count == 1) {
        r.box = node.bounds;
        r.prim = prim_indices[node.first];
        r.triangles = 1;
        r.leaf = 1;
        out[i] = r;
        return;
    }
    RefineRef* refs = scratch + extra_base;
    const uint32_t count = node.count;
    for (uint32_t k = 0; k < count; ++k) {
        const uint32_t prim = prim_indices[node.first + k];
        Box3f box = triangles[prim].bounds();
        box.lo = max(box.lo, node.bounds.lo);
        box.hi = min(box.hi, node.bounds.hi);
        // Spatial-split leaves are clipped; a reference whose triangle box
        // misses its leaf box (builder rounding) keeps the leaf box.
        if (box.is_empty()) box = node.bounds;
        const Vec3f centroid(add_rn(mul_rn(box.lo.x, 0.5f), mul_rn(box.hi.x, 0.5f)),
                             add_rn(mul_rn(box.lo.y, 0.5f), mul_rn(box.hi.y, 0.5f)),
                             add_rn(mul_rn(box.lo.z, 0.5f), mul_rn(box.hi.z, 0.5f)));
        refs[k] = {box, centroid, prim};
    }
    struct Range {
        uint32_t begin, end, refined;
    };
    Range stack[64];  // depth first: at most one pending range per level (< 33 levels)
    int top = 0;
    stack[top++] = {0, count, i};
    uint32_t next = n + extra_base;  // the next free pair
    while (top > 0) {
        const Range g = stack[--top];
        Box3f box, centroids;
        for (uint32_t k = g.begin; k < g.end; ++k) {
            box.extend(refs[k].box);
            centroids.extend(refs[k].centroid);
        }
        RefinedNode m{};
        m.box = box;
        m.triangles = g.end - g.begin;
        if (g.end - g.begin == 1) {
            m.prim = refs[g.begin].prim;
            m.leaf = 1;
            out[g.refined] = m;
            continue;
        }
        const int axis = centroids.largest_axis();
        for (uint32_t k = g.begin + 1; k < g.end; ++k) {  // insertion sort: leaves are small
            const RefineRef x = refs[k];
            uint32_t j = k;
            for (; j > g.begin && ref_before(x, refs[j - 1], axis); --j) refs[j] = refs[j - 1];
            refs[j] = x;
        }
        const uint32_t mid = g.begin + (g.end - g.begin) / 2;
        m.left = next;
        next += 2;
        out[g.refined] = m;
        stack[top++] = {mid, g.end, m.left + 1};
        stack[top++] = {g.begin, mid, m.left};
    }
}

}  // namespace rf::cwbvh
