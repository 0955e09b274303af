// Conversion of the canonical BVH to the compressed 8-wide BVH of Ylitie,
// Karras and Laine 2017 ("Efficient Incoherent Ray Traversal on GPUs Through
// Compressed Wide BVHs"): leaf refinement to single triangles, the section 3
// cost-optimal collapse with leaves of at most three triangles, then the
// section 4 node encoding: octant slot order (section 4.2, the optimal
// child-to-slot assignment found with Bertsekas' auction algorithm) and
// 8-bit child box quantisation.
// See cwbvh_layout.h for the format. The per-node steps (DP, slot
// assignment, quantisation, node encoding) live in cwbvh_collapse_steps.h and
// cwbvh_encode_steps.h, shared with the device conversion
// (backend/cuda/layout_convert.cu), which must give this file's result.
#include "accel/bvh/layout/cwbvh_layout.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "accel/bvh/layout/cwbvh_encode_steps.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

using cwbvh::RefinedNode;

Box3f intersect(const Box3f& a, const Box3f& b) {
    Box3f r;
    r.lo = max(a.lo, b.lo);
    r.hi = min(a.hi, b.hi);
    return r;
}

// Builds the refined tree in parent-before-children order, validating the
// canonical BVH on the way (links forward and in range, primitive ranges
// and indices in range).
std::vector<RefinedNode> refine(const Bvh& bvh, std::span<const Triangle> triangles) {
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

// The paper's DP (section 3) on the CPU: the shared per-node step
// (cwbvh_collapse_steps.h), children before parents (reverse index order).
class Collapse {
public:
    explicit Collapse(const std::vector<RefinedNode>& nodes) : choice_(nodes.size()) {
        const float bias = cwbvh::area_bias(nodes[0].box);
        std::vector<float> cost(nodes.size() * kCwbvhWidth);
        for (size_t n = nodes.size(); n-- > 0;)
            cwbvh::solve_node(nodes.data(), static_cast<uint32_t>(n), bias, cost.data(), choice_.data());
    }
    [[nodiscard]] const cwbvh::Choice* choices() const { return choice_.data(); }

private:
    std::vector<cwbvh::Choice> choice_;
};

}  // namespace

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

CwbvhBvh build_cwbvh(const Bvh& bvh, std::span<const Triangle> triangles) {
    CwbvhBvh out;
    if (bvh.nodes.empty()) return out;
    if (bvh.prim_indices.size() >= std::numeric_limits<uint32_t>::max())
        throw Error("build_cwbvh: too many triangle references");
    const std::vector<RefinedNode> refined = refine(bvh, triangles);
    const Collapse collapse(refined);
    const RefinedNode* nodes = refined.data();
    const cwbvh::Choice* choices = collapse.choices();
    out.nodes.reserve(refined.size() / 4 + 1);
    out.triangles.reserve(bvh.prim_indices.size());

    // Depth-first emission: a wide node's inner children are allocated
    // contiguously when it is emitted (the numbering the device reproduces).
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

        uint32_t child_in_slot[kCwbvhWidth];
        cwbvh::assign_slots(nodes, choices, p.refined, child_in_slot);
        const cwbvh::OwnCounts own = cwbvh::own_counts(nodes, choices, child_in_slot);
        const auto base_child = static_cast<uint32_t>(out.nodes.size());
        const auto base_triangle = static_cast<uint32_t>(out.triangles.size());
        out.triangles.resize(out.triangles.size() + own.triangles);
        uint32_t inner[kCwbvhWidth];
        int inner_count = 0;
        uint32_t leaf_slots = 0;
        if (!cwbvh::encode_node(nodes, choices, triangles.data(), child_in_slot, base_child, base_triangle,
                                out.nodes[p.wide], out.triangles.data() + base_triangle, inner, inner_count,
                                leaf_slots))
            throw Error("build_cwbvh: a box cannot be quantised (coordinates too large)");
        out.leaf_count += leaf_slots;
        out.nodes.resize(out.nodes.size() + own.inner);
        // Depth-first, first slot on top.
        for (int i = inner_count; i-- > 0;)
            pending.push_back({inner[i], base_child + static_cast<uint32_t>(i), p.depth + 1});
    }
    return out;
}

}  // namespace rf
