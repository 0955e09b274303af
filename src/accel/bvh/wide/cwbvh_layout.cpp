// Conversion of the canonical BVH to the compressed 8-wide BVH of Ylitie,
// Karras and Laine 2017 ("Efficient Incoherent Ray Traversal on GPUs Through
// Compressed Wide BVHs"): leaf refinement to single triangles, the section 3
// cost-optimal collapse with leaves of at most three triangles, then the
// section 4 node encoding: octant slot order (section 4.2, the optimal
// child-to-slot assignment found with Bertsekas' auction algorithm) and
// 8-bit child box quantisation.
// See cwbvh_layout.h for the format.
#include "accel/bvh/wide/cwbvh_layout.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "rayforge/core/error.h"

namespace rf {

namespace {

// Relative costs of the paper (section 3): one node fetch and box test of
// its children, one triangle test.
constexpr float kNodeCost = 1.0f;
constexpr float kTriangleCost = 0.3f;

// A node of the canonical BVH with its leaves split down to single
// triangles, the input the paper's DP expects. Children of an inner node sit
// at `left` and `left + 1`, always after their parent.
struct RefinedNode {
    Box3f box;
    uint32_t left = 0;   // inner: first child
    uint32_t prim = 0;   // leaf: triangle index
    uint32_t triangles = 0;  // in the subtree
    bool leaf = false;
};

Box3f intersect(const Box3f& a, const Box3f& b) {
    Box3f r;
    r.lo = max(a.lo, b.lo);
    r.hi = min(a.hi, b.hi);
    return r;
}

// Builds the refined tree in parent-before-children order, validating the
// canonical BVH on the way (links forward and in range, primitive ranges
// and indices in range).
std::vector<RefinedNode> refine(const Bvh& bvh, const std::vector<Triangle>& triangles) {
    std::vector<RefinedNode> out;
    out.reserve(2 * bvh.prim_indices.size() + 1);
    out.emplace_back();
    struct Pending {
        uint32_t canonical;
        uint32_t refined;
    };
    std::vector<Pending> pending{{0, 0}};
    // A leaf's references, split at the median of their centroids.
    struct Ref {
        Box3f box;  // triangle bounds clipped to the leaf's box
        Vec3f centroid;
        uint32_t prim;
    };
    std::vector<Ref> refs;
    struct Range {
        uint32_t begin, end, refined;
    };
    std::vector<Range> ranges;
    while (!pending.empty()) {
        const Pending p = pending.back();
        pending.pop_back();
        const BvhNode& node = bvh.nodes[p.canonical];
        if (!node.is_leaf()) {
            if (node.first <= p.canonical || size_t{node.first} + 1 >= bvh.nodes.size())
                throw Error("build_cwbvh: child link out of range");
            const auto left = static_cast<uint32_t>(out.size());
            out[p.refined].box = node.bounds;
            out[p.refined].left = left;
            out.emplace_back();
            out.emplace_back();
            pending.push_back({node.first + 1, left + 1});
            pending.push_back({node.first, left});
            continue;
        }
        if (size_t{node.first} + node.count > bvh.prim_indices.size())
            throw Error("build_cwbvh: leaf primitive range out of bounds");
        refs.clear();
        for (uint32_t slot = node.first; slot < node.first + node.count; ++slot) {
            const uint32_t prim = bvh.prim_indices[slot];
            if (prim >= triangles.size())
                throw Error("build_cwbvh: primitive index " + std::to_string(prim) + " out of range");
            Box3f box = intersect(triangles[prim].bounds(), node.bounds);
            // Spatial-split leaves are clipped; a reference whose triangle
            // box misses its leaf box (builder rounding) keeps the leaf box.
            if (box.is_empty()) box = node.bounds;
            refs.push_back({box, box.lo * 0.5f + box.hi * 0.5f, prim});
        }
        if (node.count == 1) {
            RefinedNode& leaf = out[p.refined];
            leaf.box = node.bounds;
            leaf.prim = refs[0].prim;
            leaf.leaf = true;
            continue;
        }
        ranges.assign(1, {0, node.count, p.refined});
        while (!ranges.empty()) {
            const Range r = ranges.back();
            ranges.pop_back();
            Box3f box, centroids;
            for (uint32_t i = r.begin; i < r.end; ++i) {
                box.extend(refs[i].box);
                centroids.extend(refs[i].centroid);
            }
            RefinedNode& n = out[r.refined];
            n.box = box;
            if (r.end - r.begin == 1) {
                n.prim = refs[r.begin].prim;
                n.leaf = true;
                continue;
            }
            const int axis = centroids.largest_axis();
            const uint32_t mid = r.begin + (r.end - r.begin) / 2;
            std::nth_element(refs.begin() + r.begin, refs.begin() + mid, refs.begin() + r.end,
                             [axis](const Ref& a, const Ref& b) {
                                 return a.centroid[axis] < b.centroid[axis] ||
                                        (a.centroid[axis] == b.centroid[axis] && a.prim < b.prim);
                             });
            const auto left = static_cast<uint32_t>(out.size());
            n.left = left;  // n may move below; written first
            out.emplace_back();
            out.emplace_back();
            ranges.push_back({mid, r.end, left + 1});
            ranges.push_back({r.begin, mid, left});
        }
    }
    // Triangle counts, children first.
    for (size_t i = out.size(); i-- > 0;) {
        RefinedNode& n = out[i];
        n.triangles = n.leaf ? 1u : out[n.left].triangles + out[n.left + 1].triangles;
    }
    return out;
}

// The paper's DP (section 3). cost[i - 1]: least cost of covering the
// subtree with at most i slots of its parent, each slot a leaf of at most
// three triangles or a wide node. choice[0]: as one slot, wide node (bit 0)
// or leaf, and as a wide node the slots its left child gets (bits 1..4).
// choice[i - 1], i >= 2: left | right << 4 slots, or 0 = one slot.
struct Choice {
    uint8_t split[kCwbvhWidth];
};

class Collapse {
public:
    explicit Collapse(const std::vector<RefinedNode>& nodes) : nodes_(nodes), choice_(nodes.size()) {
        const float root_area = nodes[0].box.surface_area();
        // Keeps zero-area subtrees from tying: fewer nodes and tests win.
        area_bias_ = root_area > 0.0f && std::isfinite(root_area) ? root_area * 1e-7f : 1.0f;
        std::vector<float> cost(nodes.size() * kCwbvhWidth);
        for (size_t n = nodes.size(); n-- > 0;) solve(n, cost);
    }

    bool inner(uint32_t b) const { return !nodes_[b].leaf && (choice_[b].split[0] & 1u) != 0; }

    // The slots of refined inner node b as a wide node; returns their number.
    int node_slots(uint32_t b, uint32_t* slots) const {
        int used = 0;
        const int k = choice_[b].split[0] >> 1;
        gather(nodes_[b].left, k, slots, used);
        gather(nodes_[b].left + 1, kCwbvhWidth - k, slots, used);
        return used;
    }

private:
    float area(size_t n) const {
        const float a = nodes_[n].box.surface_area();
        return (std::isfinite(a) ? a : std::numeric_limits<float>::max()) + area_bias_;
    }

    void solve(size_t n, std::vector<float>& cost) {
        constexpr float kInf = std::numeric_limits<float>::infinity();
        const RefinedNode& node = nodes_[n];
        float* c = &cost[n * kCwbvhWidth];
        Choice& choice = choice_[n];
        if (node.leaf) {
            for (int i = 0; i < kCwbvhWidth; ++i) {
                c[i] = area(n) * kTriangleCost;
                choice.split[i] = 0;
            }
            return;
        }
        const float* left = &cost[size_t{node.left} * kCwbvhWidth];
        const float* right = &cost[(size_t{node.left} + 1) * kCwbvhWidth];
        // dist[j - 1]: both children sharing at most j slots, the left one
        // getting dist_k[j - 1].
        float dist[kCwbvhWidth];
        int dist_k[kCwbvhWidth];
        dist[0] = kInf;
        dist_k[0] = 0;
        for (int j = 2; j <= kCwbvhWidth; ++j) {
            dist[j - 1] = kInf;
            dist_k[j - 1] = 1;
            for (int k = 1; k < j; ++k) {
                const float s = left[k - 1] + right[j - k - 1];
                if (s < dist[j - 1]) {
                    dist[j - 1] = s;
                    dist_k[j - 1] = k;
                }
            }
        }
        const float as_node = area(n) * kNodeCost + dist[kCwbvhWidth - 1];
        const float as_leaf = node.triangles <= uint32_t(kCwbvhMaxLeafTriangles)
                                  ? area(n) * kTriangleCost * float(node.triangles)
                                  : kInf;
        const bool is_inner = as_node < as_leaf;
        c[0] = is_inner ? as_node : as_leaf;
        choice.split[0] = uint8_t((is_inner ? 1u : 0u) | (unsigned(dist_k[kCwbvhWidth - 1]) << 1));
        uint8_t split = 0;  // one slot
        for (int i = 2; i <= kCwbvhWidth; ++i) {
            if (dist[i - 1] < c[i - 2]) {
                c[i - 1] = dist[i - 1];
                split = uint8_t(dist_k[i - 1] | ((i - dist_k[i - 1]) << 4));
            } else {
                c[i - 1] = c[i - 2];
            }
            choice.split[i - 1] = split;
        }
    }

    // Appends the slots that cover subtree n with at most i slots.
    void gather(uint32_t n, int i, uint32_t* slots, int& used) const {
        const uint8_t s = i >= 2 ? choice_[n].split[i - 1] : uint8_t(0);
        if (s == 0) {
            slots[used++] = n;
            return;
        }
        gather(nodes_[n].left, s & 15, slots, used);
        gather(nodes_[n].left + 1, s >> 4, slots, used);
    }

    const std::vector<RefinedNode>& nodes_;
    std::vector<Choice> choice_;
    float area_bias_ = 1.0f;
};

float dequantize(float p, int q, float step) { return p + float(q) * step; }

}  // namespace

void cwbvh_slot_costs(const Box3f* child_boxes, int count, double (&cost)[kCwbvhWidth][kCwbvhWidth]) {
    // In double: finite for every pair of finite float boxes.
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

void cwbvh_assign_slots_greedy(const double (&cost)[kCwbvhWidth][kCwbvhWidth], int count,
                               int (&slot_of)[kCwbvhWidth]) {
    bool slot_taken[kCwbvhWidth] = {};
    for (int c = 0; c < kCwbvhWidth; ++c) slot_of[c] = -1;
    for (int round = 0; round < count; ++round) {
        int best_c = -1, best_s = -1;
        for (int c = 0; c < count; ++c) {
            if (slot_of[c] >= 0) continue;
            for (int s = 0; s < kCwbvhWidth; ++s) {
                if (slot_taken[s]) continue;
                // `!(>=)` so that a NaN never blocks the first pick.
                if (best_c < 0 || !(cost[c][s] >= cost[best_c][best_s])) {
                    best_c = c;
                    best_s = s;
                }
            }
        }
        slot_of[best_c] = best_s;
        slot_taken[best_s] = true;
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
void cwbvh_assign_slots_auction(const double (&cost)[kCwbvhWidth][kCwbvhWidth], int count,
                                int (&slot_of)[kCwbvhWidth]) {
    constexpr int n = kCwbvhWidth;
    // 8 * kFinalEps < 1e-6: the documented bound, relative to the cost range.
    constexpr double kFinalEps = 1e-6 / 9.0;
    for (int c = 0; c < n; ++c) slot_of[c] = -1;
    count = std::clamp(count, 0, n);
    if (count == 0) return;

    // Normalisation. Scaling by a power of two first (exact) keeps
    // hi - lo finite for costs anywhere in the double range.
    double largest = 0.0;
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (std::isfinite(cost[c][s])) largest = std::max(largest, std::fabs(cost[c][s]));
        }
    }
    int exponent = 0;
    if (largest > 0.0) std::frexp(largest, &exponent);
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (!std::isfinite(cost[c][s])) continue;
            const double x = std::ldexp(cost[c][s], -exponent);
            lo = std::min(lo, x);
            hi = std::max(hi, x);
        }
    }
    const double range = hi - lo;  // in [0, 2]; 0 (or -inf: no finite cost): all ties
    double benefit[n][n] = {};
    for (int c = 0; c < count; ++c) {
        for (int s = 0; s < n; ++s) {
            if (!std::isfinite(cost[c][s])) {
                benefit[c][s] = -1.0;  // below every finite cost's benefit
            } else if (range > 0.0) {
                benefit[c][s] = (hi - std::ldexp(cost[c][s], -exponent)) / range;
            }
        }
    }

    double price[n] = {};
    int holder[n];     // slot -> bidder, -1 for none
    int held[n];       // bidder -> slot, -1 for none
    int waiting[n];    // unassigned bidders (a stack)
    for (double eps = 1.0;; eps = std::max(eps * 0.125, kFinalEps)) {
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
            double second_value = -std::numeric_limits<double>::infinity();
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

bool cwbvh_quantize(CwbvhNode& node, const Box3f (&boxes)[kCwbvhWidth], unsigned used) {
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
        if (!std::isfinite(lo) || !std::isfinite(hi) || lo > hi) return false;
        // Smallest power of two step with 255 steps covering the extent.
        const double extent = double(hi) - double(lo);
        int e = 1;
        if (extent > 0.0) {
            int exponent;
            const double mantissa = std::frexp(extent / 255.0, &exponent);  // in [0.5, 1)
            const int power = mantissa == 0.5 ? exponent - 1 : exponent;
            e = std::clamp(power + 127, 1, 254);
        }
        // Rounded up until p + 255 step reaches hi in float; 255 step must
        // stay finite so that q * step is exact for every q.
        while (!(dequantize(lo, 255, cwbvh_step(uint8_t(e))) >= hi)) {
            if (e == 254) return false;
            ++e;
        }
        if (!std::isfinite(255.0f * cwbvh_step(uint8_t(e)))) return false;
        node.p[a] = lo;
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
            int ql = int(std::clamp(std::floor((double(lo) - double(p)) / double(step)), 0.0, 255.0));
            while (ql > 0 && dequantize(p, ql, step) > lo) --ql;
            int qh = int(std::clamp(std::ceil((double(hi) - double(p)) / double(step)), 0.0, 255.0));
            while (qh < 255 && dequantize(p, qh, step) < hi) ++qh;
            if (dequantize(p, ql, step) > lo || dequantize(p, qh, step) < hi) return false;
            q_lo[a][s] = uint8_t(ql);
            q_hi[a][s] = uint8_t(qh);
        }
    }
    return true;
}

CwbvhBvh build_cwbvh(const Bvh& bvh, const std::vector<Triangle>& triangles) {
    CwbvhBvh out;
    if (bvh.nodes.empty()) return out;
    if (bvh.prim_indices.size() >= std::numeric_limits<uint32_t>::max())
        throw Error("build_cwbvh: too many triangle references");
    const std::vector<RefinedNode> refined = refine(bvh, triangles);
    const Collapse collapse(refined);
    out.nodes.reserve(refined.size() / 4 + 1);
    out.triangles.reserve(bvh.prim_indices.size());

    struct Pending {
        uint32_t refined;  // covered by this wide node
        uint32_t wide;
        int depth;
    };
    std::vector<Pending> pending{{0, 0, 1}};
    out.nodes.emplace_back();
    while (!pending.empty()) {
        const Pending p = pending.back();
        pending.pop_back();
        out.depth = std::max(out.depth, p.depth);
        if (p.depth > kCwbvhMaxDepth)
            throw Error("build_cwbvh: wide BVH deeper than " + std::to_string(kCwbvhMaxDepth) + " levels");

        // The children: a refined leaf as the root is a one-slot node.
        uint32_t children[kCwbvhWidth];
        int count = 1;
        if (refined[p.refined].leaf) {
            children[0] = p.refined;
        } else {
            count = collapse.node_slots(p.refined, children);
        }
        Box3f child_box[kCwbvhWidth];
        for (int c = 0; c < count; ++c) child_box[c] = refined[children[c]].box;
        double slot_cost[kCwbvhWidth][kCwbvhWidth] = {};
        cwbvh_slot_costs(child_box, count, slot_cost);
        int slot_of[kCwbvhWidth];
        cwbvh_assign_slots_auction(slot_cost, count, slot_of);
        int child_in[kCwbvhWidth];  // slot -> child, -1 for empty
        std::fill(child_in, child_in + kCwbvhWidth, -1);
        for (int c = 0; c < count; ++c) child_in[slot_of[c]] = c;

        CwbvhNode node{};
        node.base_index_child = static_cast<uint32_t>(out.nodes.size());
        node.base_index_triangle = static_cast<uint32_t>(out.triangles.size());
        Box3f slot_box[kCwbvhWidth];
        unsigned used = 0;
        uint32_t rank = 0;
        int offset = 0;
        Pending inner[kCwbvhWidth];
        int inner_count = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            if (child_in[s] < 0) continue;
            const uint32_t b = children[child_in[s]];
            slot_box[s] = child_box[child_in[s]];
            used |= 1u << s;
            if (collapse.inner(b)) {
                node.imask = uint8_t(node.imask | (1u << s));
                node.meta[s] = cwbvh_inner_meta(s);
                inner[inner_count++] = {b, node.base_index_child + rank++, p.depth + 1};
                continue;
            }
            // A leaf slot: the subtree's triangles (at most three, by the DP).
            uint32_t stack[2 * kCwbvhMaxLeafTriangles];
            int top = 0, leaf_count = 0;
            stack[top++] = b;
            while (top > 0) {
                const RefinedNode& n = refined[stack[--top]];
                if (n.leaf) {
                    const Triangle& tri = triangles[n.prim];
                    float w;
                    std::memcpy(&w, &n.prim, sizeof w);
                    out.triangles.push_back({{tri.v0.x, tri.v0.y, tri.v0.z, w},
                                             {tri.v1.x, tri.v1.y, tri.v1.z, 0.0f},
                                             {tri.v2.x, tri.v2.y, tri.v2.z, 0.0f}});
                    ++leaf_count;
                } else {
                    stack[top++] = n.left + 1;
                    stack[top++] = n.left;
                }
            }
            node.meta[s] = cwbvh_leaf_meta(leaf_count, offset);
            offset += leaf_count;
            ++out.leaf_count;
        }
        if (!cwbvh_quantize(node, slot_box, used))
            throw Error("build_cwbvh: a box cannot be quantised (coordinates too large)");
        out.nodes[p.wide] = node;
        out.nodes.resize(out.nodes.size() + rank);
        // Depth-first, first slot on top.
        for (int i = inner_count; i-- > 0;) pending.push_back(inner[i]);
    }
    return out;
}

}  // namespace rf
