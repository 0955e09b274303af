// The per-node encoding of the compressed 8-wide BVH of Ylitie, Karras and
// Laine 2017 (HPG 2017), section 4: octant slot assignment (section 4.2,
// Bertsekas' auction algorithm on dot(child centre - node centre, octant
// diagonal)), 8-bit child boxes on a power-of-two grid (section 4.1), the
// meta bytes and the leaf triangles of one wide node. Host and device code,
// shared by build_cwbvh (cwbvh_layout.cpp) and the device conversion
// (backend/cuda/layout_convert.cu). Included at the end of cwbvh_layout.h,
// which declares the three public steps and describes the format.
//
// Only exact operations and single roundings that FMA contraction cannot
// change are used (frexp/ldexp/floor/ceil, sums of exact products), so host
// and device take the same decisions.
#pragma once

#include <math.h>

#include <cstdint>
#include <limits>

#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "accel/bvh/layout/cwbvh_layout.h"

namespace rf {

namespace cwbvh {

RF_HDI bool finite_d(double x) { return x - x == 0.0; }  // false for inf and NaN
RF_HDI int clamp_i(int x, int lo, int hi) { return x < lo ? lo : (x > hi ? hi : x); }
RF_HDI double clamp_d(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }
RF_HDI float dequantize(float p, int q, float step) { return p + float(q) * step; }

inline constexpr uint32_t kNoChild = 0xFFFFFFFFu;

}  // namespace cwbvh

RF_HDI void cwbvh_slot_costs(const Box3f* child_boxes, int count, double (&cost)[kCwbvhWidth][kCwbvhWidth]) {
    // In double: finite for every pair of finite float boxes. 0.5 * x is
    // exact, so a fused multiply-add rounds the centres the same way.
    Box3f node_box;
    for (int c = 0; c < count; ++c) node_box.extend(child_boxes[c]);
    double centre[3];
    for (int a = 0; a < 3; ++a) centre[a] = 0.5 * double(node_box.lo[a]) + 0.5 * double(node_box.hi[a]);
    for (int c = 0; c < count; ++c) {
        double offset[3];
        for (int a = 0; a < 3; ++a)
            offset[a] = 0.5 * double(child_boxes[c].lo[a]) + 0.5 * double(child_boxes[c].hi[a]) - centre[a];
        for (int s = 0; s < kCwbvhWidth; ++s) {
            cost[c][s] = ((s & 1) ? -offset[0] : offset[0]) + ((s & 2) ? -offset[1] : offset[1]) +
                         ((s & 4) ? -offset[2] : offset[2]);
        }
    }
}

// Auction algorithm for the assignment problem (D. P. Bertsekas, "The
// auction algorithm: a distributed relaxation method for the assignment
// problem", Annals of Operations Research 14, 1988), with epsilon scaling.
// Children bid for slots; the benefit of slot s to child c is the
// normalised negated cost, in [0, 1]. To make the problem square (eight
// bidders, eight objects), the 8 - count missing children are dummies
// that value every slot at zero: they only take the slots nobody needs, so
// an optimal square assignment restricted to the real children is an
// optimal injective one, and the square problem keeps the textbook
// guarantees under epsilon scaling (the asymmetric one would need reverse
// auction steps).
//
// A round: an unassigned bidder takes the slot j1 of highest value
// benefit - price, raising its price by (best value - second best value +
// eps) and evicting its previous holder. Every bid raises a price by at
// least eps, so each round ends after finitely many bids; at its end every
// bidder holds a slot within eps of its best value (eps-complementary
// slackness), hence the total benefit is within 8 * eps of the maximum.
// Prices carry over from round to round while eps shrinks by 8 from the
// benefit range (1) to kFinalEps, which keeps every round short.
RF_HDI void cwbvh_assign_slots_auction(const double (&cost)[kCwbvhWidth][kCwbvhWidth], int count,
                                       int (&slot_of)[kCwbvhWidth]) {
    constexpr int n = kCwbvhWidth;
    // 8 * kFinalEps < 1e-6: the documented bound, relative to the cost range.
    constexpr double kFinalEps = 1e-6 / 9.0;
    const double kInf = std::numeric_limits<double>::infinity();
    for (int c = 0; c < n; ++c) slot_of[c] = -1;
    count = cwbvh::clamp_i(count, 0, n);
    if (count == 0) return;

    // Normalisation. Scaling by a power of two first (exact) keeps
    // hi - lo finite for costs anywhere in the double range.
    double largest = 0.0;
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (cwbvh::finite_d(cost[c][s]) && fabs(cost[c][s]) > largest) largest = fabs(cost[c][s]);
        }
    }
    int exponent = 0;
    if (largest > 0.0) (void)frexp(largest, &exponent);
    double lo = kInf, hi = -kInf;
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (!cwbvh::finite_d(cost[c][s])) continue;
            const double x = ldexp(cost[c][s], -exponent);
            if (x < lo) lo = x;
            if (x > hi) hi = x;
        }
    }
    const double range = hi - lo;  // in [0, 2]; 0 (or -inf: no finite cost): all ties
    double benefit[n][n] = {};
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (!cwbvh::finite_d(cost[c][s])) {
                benefit[c][s] = -1.0;  // below every finite cost's benefit
            } else if (range > 0.0) {
                benefit[c][s] = (hi - ldexp(cost[c][s], -exponent)) / range;
            }
        }
    }

    double price[n] = {};
    int holder[n];   // slot -> bidder, -1 for none
    int held[n];     // bidder -> slot, -1 for none
    int waiting[n];  // unassigned bidders (a stack)
    for (double eps = 1.0;; eps = eps * 0.125 > kFinalEps ? eps * 0.125 : kFinalEps) {
        int waiting_count = 0;
        for (int i = 0; i < n; ++i) {
            holder[i] = -1;
            held[i] = -1;
            waiting[waiting_count++] = n - 1 - i;
        }
        while (waiting_count > 0) {
            const int bidder = waiting[--waiting_count];
            int best = 0;
            double best_value = benefit[bidder][0] - price[0];
            double second_value = -kInf;
            for (int s = 1; s < n; ++s) {
                const double value = benefit[bidder][s] - price[s];
                if (value > best_value) {
                    second_value = best_value;
                    best_value = value;
                    best = s;
                } else if (value > second_value) {
                    second_value = value;
                }
            }
            price[best] += best_value - second_value + eps;
            if (holder[best] >= 0) {
                held[holder[best]] = -1;
                waiting[waiting_count++] = holder[best];
            }
            holder[best] = bidder;
            held[bidder] = best;
        }
        if (eps <= kFinalEps) break;
    }
    for (int c = 0; c < count; ++c) slot_of[c] = held[c];
}

RF_HDI bool cwbvh_quantize(CwbvhNode& node, const Box3f (&boxes)[kCwbvhWidth], unsigned used) {
    using cwbvh::dequantize;
    uint8_t* q_lo[3] = {node.q_lo_x, node.q_lo_y, node.q_lo_z};
    uint8_t* q_hi[3] = {node.q_hi_x, node.q_hi_y, node.q_hi_z};
    Box3f box;
    for (int s = 0; s < kCwbvhWidth; ++s) {
        for (int a = 0; a < 3; ++a) q_lo[a][s] = q_hi[a][s] = 0;
        if ((used >> s) & 1u) box.extend(boxes[s]);
    }
    for (int a = 0; a < 3; ++a) {
        node.p[a] = 0.0f;
        node.e[a] = 127;
    }
    if (used == 0) return true;
    for (int a = 0; a < 3; ++a) {
        const float lo = box.lo[a], hi = box.hi[a];
        if (!cwbvh::finite(lo) || !cwbvh::finite(hi) || lo > hi) return false;
        // Smallest power of two step with 255 steps covering the extent.
        const double extent = double(hi) - double(lo);
        int e = 1;
        if (extent > 0.0) {
            int exponent;
            const double mantissa = frexp(extent / 255.0, &exponent);  // in [0.5, 1)
            const int power = mantissa == 0.5 ? exponent - 1 : exponent;
            e = cwbvh::clamp_i(power + 127, 1, 254);
        }
        // Rounded up until p + 255 step reaches hi in float; 255 step must
        // stay finite so that q * step is exact for every q.
        while (!(dequantize(lo, 255, cwbvh_step(uint8_t(e))) >= hi)) {
            if (e == 254) return false;
            ++e;
        }
        if (!cwbvh::finite(255.0f * cwbvh_step(uint8_t(e)))) return false;
        // +0 for either zero: unions taken in different orders (CPU and
        // device) may disagree on the sign, never on the value.
        node.p[a] = lo == 0.0f ? 0.0f : lo;
        node.e[a] = uint8_t(e);
    }
    for (int s = 0; s < kCwbvhWidth; ++s) {
        if (!((used >> s) & 1u)) continue;
        for (int a = 0; a < 3; ++a) {
            const float p = node.p[a], step = cwbvh_step(node.e[a]);
            const float lo = boxes[s].lo[a], hi = boxes[s].hi[a];
            if (!(lo <= hi)) return false;
            // Estimate in double, then correct with the float formula the
            // traversal uses until the box is conservative.
            int ql = int(cwbvh::clamp_d(floor((double(lo) - double(p)) / double(step)), 0.0, 255.0));
            while (ql > 0 && dequantize(p, ql, step) > lo) --ql;
            int qh = int(cwbvh::clamp_d(ceil((double(hi) - double(p)) / double(step)), 0.0, 255.0));
            while (qh < 255 && dequantize(p, qh, step) < hi) ++qh;
            if (dequantize(p, ql, step) > lo || dequantize(p, qh, step) < hi) return false;
            q_lo[a][s] = uint8_t(ql);
            q_hi[a][s] = uint8_t(qh);
        }
    }
    return true;
}

namespace cwbvh {

// Section 4.2 for the wide node covering refined node b: its slots (a
// refined leaf as the root is a one-slot node), their octant costs and the
// auction. child_in_slot[s]: the refined node in slot s, or kNoChild.
RF_HDI void assign_slots(const RefinedNode* nodes, const Choice* choices, uint32_t b,
                         uint32_t (&child_in_slot)[kWidth]) {
    uint32_t children[kWidth];
    int count = 1;
    if (nodes[b].leaf) {
        children[0] = b;
    } else {
        count = node_slots(nodes, choices, b, children);
    }
    Box3f child_box[kWidth];
    for (int c = 0; c < count; ++c) child_box[c] = nodes[children[c]].box;
    double slot_cost[kWidth][kWidth] = {};
    cwbvh_slot_costs(child_box, count, slot_cost);
    int slot_of[kWidth];
    cwbvh_assign_slots_auction(slot_cost, count, slot_of);
    for (int s = 0; s < kWidth; ++s) child_in_slot[s] = kNoChild;
    for (int c = 0; c < count; ++c) child_in_slot[slot_of[c]] = children[c];
}

// What one wide node adds besides its subtrees: its inner children (wide
// nodes) and the triangles of its leaf slots.
struct OwnCounts {
    uint32_t inner;
    uint32_t triangles;
};

RF_HDI OwnCounts own_counts(const RefinedNode* nodes, const Choice* choices,
                            const uint32_t (&child_in_slot)[kWidth]) {
    OwnCounts own{0u, 0u};
    for (int s = 0; s < kWidth; ++s) {
        const uint32_t b = child_in_slot[s];
        if (b == kNoChild) continue;
        if (is_wide_node(nodes, choices, b)) {
            ++own.inner;
        } else {
            own.triangles += nodes[b].triangles;
        }
    }
    return own;
}

// Writes the wide node (its inner children at base_child.., its triangles at
// base_triangle..) and its leaf triangles to tri_out[0 .. own.triangles),
// each leaf slot's in depth-first order. inner_children[r]: the refined
// node of the r-th inner slot. Returns false when a box cannot be quantised.
RF_HDI bool encode_node(const RefinedNode* nodes, const Choice* choices, const Triangle* triangles,
                        const uint32_t (&child_in_slot)[kWidth], uint32_t base_child, uint32_t base_triangle,
                        CwbvhNode& node, CwbvhTriangle* tri_out, uint32_t (&inner_children)[kWidth],
                        int& inner_count, uint32_t& leaf_slots) {
    node = CwbvhNode{};
    node.base_index_child = base_child;
    node.base_index_triangle = base_triangle;
    Box3f slot_box[kWidth];
    unsigned used = 0;
    int offset = 0;
    inner_count = 0;
    leaf_slots = 0;
    for (int s = 0; s < kWidth; ++s) {
        const uint32_t b = child_in_slot[s];
        if (b == kNoChild) continue;
        slot_box[s] = nodes[b].box;
        used |= 1u << s;
        if (is_wide_node(nodes, choices, b)) {
            node.imask = uint8_t(node.imask | (1u << s));
            node.meta[s] = cwbvh_inner_meta(s);
            inner_children[inner_count++] = b;
            continue;
        }
        // A leaf slot: the subtree's triangles (at most three, by the DP).
        uint32_t stack[2 * kMaxLeafTriangles];
        int top = 0, count = 0;
        stack[top++] = b;
        while (top > 0) {
            const RefinedNode& n = nodes[stack[--top]];
            if (n.leaf) {
                const Triangle& tri = triangles[n.prim];
                tri_out[offset + count] = {{tri.v0.x, tri.v0.y, tri.v0.z, bits_to_float(n.prim)},
                                           {tri.v1.x, tri.v1.y, tri.v1.z, 0.0f},
                                           {tri.v2.x, tri.v2.y, tri.v2.z, 0.0f}};
                ++count;
            } else {
                stack[top++] = n.left + 1;
                stack[top++] = n.left;
            }
        }
        node.meta[s] = cwbvh_leaf_meta(count, offset);
        offset += count;
        ++leaf_slots;
    }
    return cwbvh_quantize(node, slot_box, used);
}

}  // namespace cwbvh
}  // namespace rf
