// The compressed 8-wide BVH (CWBVH) of Ylitie, Karras and Laine 2017,
// "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs"
// (HPG 2017), section 4.1: 80-byte nodes whose eight child boxes are stored
// as 8-bit offsets on a per-node grid, converted from the canonical binary
// BVH (rayforge/accel/bvh/bvh.h).
//
// Node (five 16-byte loads on the GPU):
//   p              origin of the quantisation grid (the node box's lo corner)
//   e[3]           biased exponents: the grid step on axis a is the power of
//                  two 2^(e[a] - 127), the smallest with 255 steps covering the
//                  node box (rounded up, so p + 255 * step >= hi in float)
//   imask          bit s set: slot s holds an inner node
//   base_index_child     the inner children, contiguous, in slot order: the
//                        child in slot s is base_index_child + (number of
//                        inner slots below s)
//   base_index_triangle  the leaf children's triangles, contiguous, in slot
//                        order
//   meta[8]        per slot: 0 = empty; inner: 0b001 << 5 | (24 + s);
//                  leaf: (unary triangle count: 0b001, 0b011 or 0b111) << 5 |
//                  (offset of its first triangle from base_index_triangle).
//                  Read as a bit mask, (meta >> 5) << (meta & 31) is exactly
//                  the bits a hit child sets in the traversal's 32-bit hit
//                  mask: bits 24..31 for inner children, 0..23 for triangles.
//   q_lo_*/q_hi_*  child box, quantised outward: lo = p + q_lo * step is
//                  <= the exact lo and hi = p + q_hi * step >= the exact hi
//                  (checked in float, with the traversal's own formula,
//                  for every child of every node).
//
// Slots are assigned by direction octant (section 4.2): slot s receives the
// child met first by rays whose direction has the sign pattern s (bit a set =
// negative along axis a), so the traversal, which visits hit children in the
// order of slot XOR ray octant, goes nearly front to back with no sorting.
// The cost of child c in slot s is dot(child centre - node centre, octant-s
// diagonal); as in the paper, the assignment minimising the summed cost is
// found with Bertsekas' auction algorithm (cwbvh_assign_slots_auction).
//
// Collapse: our own implementation of the paper's section 3 dynamic
// programme with leaves of at most three triangles (the unary count in
// meta). The paper starts from a BVH with one triangle per leaf; canonical
// leaves of several triangles are therefore first split into binary
// subtrees of single triangles (median split along the leaf's longest axis of
// triangle centroids, child boxes clipped to the leaf's box so spatial-split
// BVHs stay valid), and the DP regroups them into leaves of one to three
// triangles where that is cheaper. Costs are the paper's: c_node = 1 per
// node, c_prim = 0.3 per triangle, each weighted by the box's surface area
// (plus a tiny constant so that zero-area subtrees still prefer fewer nodes).
// collapse_bvh<8> (wide_bvh.h) could not be reused: it never splits a binary
// leaf and counts 4-triangle packs.
// The steps are shared with the device conversion (rf::cuda::
// build_cwbvh_on_device, backend/cuda/layout_convert.cu), which gives the
// same arrays: cwbvh_refine_steps.h, cwbvh_collapse_steps.h (the DP),
// cwbvh_encode_steps.h (slots, quantisation, node encoding) and
// cwbvh_emit_steps.h (the depth-first numbering level by level).
//
// Triangles are stored as their original vertices (three float4s, the
// triangle index bit-cast into v0.w), as in aila_laine_layout.h, so the
// shared traversal's hits are bit-identical to the scalar watertight test.
//
// The traversal's fixed stack holds at most one node group per wide level
// below the root (kCwbvhStackSize), plus as many postponed triangle groups
// (trace/cwbvh_traversal.h); build_cwbvh throws rf::Error when the wide tree is deeper than
// kCwbvhMaxDepth (never seen: the tree is several times shallower than the
// binary one), and also when a box cannot be quantised in float (scene
// extents near FLT_MAX).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

inline constexpr int kCwbvhWidth = 8;
inline constexpr int kCwbvhMaxLeafTriangles = 3;
// Node groups on the traversal stack (8 bytes each) and the deepest wide
// tree (in nodes, root included) it can traverse: one node group per level
// below the root. The traversal's stack is twice this (postponed triangle
// groups, kCwbvhTraversalStackSize in trace/cwbvh_traversal.h).
inline constexpr int kCwbvhStackSize = 32;
inline constexpr int kCwbvhMaxDepth = kCwbvhStackSize + 1;

// Set bits of x (a node's inner slots below a slot, a leaf's unary count).
RF_HDI uint32_t cwbvh_popc(uint32_t x) {
#if defined(__CUDA_ARCH__)
    return static_cast<uint32_t>(__popc(x));
#else
    return static_cast<uint32_t>(__builtin_popcount(x));
#endif
}

// meta byte helpers: empty slot, inner-node marker and leaf encoding.
inline constexpr uint8_t kCwbvhEmptyMeta = 0;
RF_HDI bool cwbvh_meta_is_inner(uint8_t meta) { return (meta & 0x18u) == 0x18u; }
RF_HDI uint8_t cwbvh_inner_meta(int slot) { return static_cast<uint8_t>((1u << 5) | (24u + unsigned(slot))); }
// count in 1..3, offset + count <= 24.
RF_HDI uint8_t cwbvh_leaf_meta(int count, int offset) {
    return static_cast<uint8_t>((((1u << unsigned(count)) - 1u) << 5) | unsigned(offset));
}

struct alignas(16) CwbvhNode {
    float p[3];
    uint8_t e[3];
    uint8_t imask;
    uint32_t base_index_child;
    uint32_t base_index_triangle;
    uint8_t meta[8];
    uint8_t q_lo_x[8];
    uint8_t q_lo_y[8];
    uint8_t q_lo_z[8];
    uint8_t q_hi_x[8];
    uint8_t q_hi_y[8];
    uint8_t q_hi_z[8];
};
static_assert(sizeof(CwbvhNode) == 80, "CwbvhNode must stay the paper's 80 bytes");

// CUDA's float4 without CUDA headers (same size and alignment).
struct alignas(16) CwbvhFloat4 {
    float x, y, z, w;
};

// One triangle: v0, v1, v2 in xyz; v0.w holds the triangle index's bits.
struct CwbvhTriangle {
    CwbvhFloat4 v0, v1, v2;
};
static_assert(sizeof(CwbvhTriangle) == 48, "CwbvhTriangle is three float4s");

// The grid step 2^(e - 127) of an exponent byte (e >= 1: a normal float).
RF_HDI float cwbvh_step(uint8_t e) {
    return bits_to_float(uint32_t(e) << 23);
}

// The dequantised box of `slot`. q * step is exact (an 8-bit integer times a
// power of two), so with or without FMA contraction every compiler gets the
// same single rounding of p + q * step: the box the builder checked.
RF_HDI Box3f cwbvh_child_box(const CwbvhNode& n, int slot) {
    const float sx = cwbvh_step(n.e[0]), sy = cwbvh_step(n.e[1]), sz = cwbvh_step(n.e[2]);
    Box3f b;
    b.lo = Vec3f(n.p[0] + float(n.q_lo_x[slot]) * sx, n.p[1] + float(n.q_lo_y[slot]) * sy,
                 n.p[2] + float(n.q_lo_z[slot]) * sz);
    b.hi = Vec3f(n.p[0] + float(n.q_hi_x[slot]) * sx, n.p[1] + float(n.q_hi_y[slot]) * sy,
                 n.p[2] + float(n.q_hi_z[slot]) * sz);
    return b;
}

// What the traversal reads; node_count == 0 is the empty BVH. Node 0 is the root.
struct CwbvhView {
    const CwbvhNode* nodes = nullptr;
    const CwbvhTriangle* triangles = nullptr;
    uint32_t node_count = 0;
    uint32_t triangle_count = 0;
};

struct CwbvhBvh {
    std::vector<CwbvhNode> nodes;
    std::vector<CwbvhTriangle> triangles;  // leaf triangles, one entry per reference
    size_t leaf_count = 0;                 // leaf slots over all nodes
    int depth = 0;                         // wide nodes on the longest root-to-leaf path

    [[nodiscard]] CwbvhView view() const {
        return {nodes.data(), triangles.data(), static_cast<uint32_t>(nodes.size()),
                static_cast<uint32_t>(triangles.size())};
    }
    [[nodiscard]] size_t memory_bytes() const {
        return nodes.size() * sizeof(CwbvhNode) + triangles.size() * sizeof(CwbvhTriangle);
    }
};

// Sets node.p, node.e and the q_* bytes from the exact child boxes of the
// slots in `used` (bit s = slot s; the others get zeros). Returns false when
// the boxes cannot be quantised conservatively in float (non-finite, or
// extents near FLT_MAX).
RF_HDI bool cwbvh_quantize(CwbvhNode& node, const Box3f (&boxes)[kCwbvhWidth], unsigned used);

// Octant slot assignment (section 4.2). cost[c][s], c < count <= 8: the
// cost of child c in slot s, dot(child centre - node centre, diagonal of
// octant s) with the diagonal's component a = -1 where s has bit a, else +1.
// Rows >= count are left untouched. Node centre: centre of the union of the
// child boxes.
RF_HDI void cwbvh_slot_costs(const Box3f* child_boxes, int count, double (&cost)[kCwbvhWidth][kCwbvhWidth]);

// Both return slot_of[c] for c < count: distinct slots in 0..7.
// Auction algorithm (Bertsekas), what build_cwbvh uses: the summed cost is
// within 1e-6 * (largest - smallest cost of the table) of the minimum over
// all injective assignments, and exactly minimal when the minimum beats every
// other assignment by more than that (integer costs of range < 1e6, say).
// Non-finite costs are treated as worse than every finite one. Terminates
// for every input.
RF_HDI void cwbvh_assign_slots_auction(const double (&cost)[kCwbvhWidth][kCwbvhWidth], int count,
                                       int (&slot_of)[kCwbvhWidth]);
// Greedy, cheapest (child, slot) pair first (what the builder used before;
// kept for comparison): can be arbitrarily worse than the optimum.
void cwbvh_assign_slots_greedy(const double (&cost)[kCwbvhWidth][kCwbvhWidth], int count,
                               int (&slot_of)[kCwbvhWidth]);

// Converts `bvh` (built over `triangles`; references from spatial splits
// allowed). Throws rf::Error when the BVH is malformed (links or primitive
// indices out of range), the wide tree is deeper than kCwbvhMaxDepth, or a
// box cannot be quantised.
CwbvhBvh build_cwbvh(const Bvh& bvh, std::span<const Triangle> triangles);

}  // namespace rf

// The definitions of the host/device steps above (and the per-node encoding).
#include "accel/bvh/layout/cwbvh_encode_steps.h"
