// Conversion of the canonical BVH to the node-pair layout of Aila and Laine
// 2009 ("Understanding the Efficiency of Ray Traversal on GPUs"), depth
// first; the node and leaf-list writers are aila_laine_steps.h's, shared with
// the device conversion (backend/cuda/layout_convert.cu).
#include "accel/bvh/layout/aila_laine_layout.h"

#include <limits>
#include <string>

#include "accel/bvh/layout/aila_laine_steps.h"
#include "rayforge/core/error.h"

namespace rf {

AilaLaineBvh convert_to_aila_laine(const Bvh& bvh, std::span<const Triangle> triangles) {
    AilaLaineBvh out;
    if (bvh.nodes.empty()) return out;
    out.bounds = bvh.nodes[0].bounds;

    const size_t canonical_count = bvh.nodes.size();
    // Links are 31-bit; node indices must also stay below the stack sentinel.
    constexpr size_t kMaxLink = static_cast<size_t>(kAilaLaineEntrySentinel);

    // Appends the leaf's triangles and its sentinel; returns its link.
    auto emit_leaf = [&](const BvhNode& leaf) -> int32_t {
        if (size_t{leaf.first} + leaf.count > bvh.prim_indices.size())
            throw Error("convert_to_aila_laine: leaf primitive range out of bounds");
        const size_t offset = out.triangles.size();
        if (offset + size_t{leaf.count} * kAilaLaineTriangleStride + 1 > kMaxLink)
            throw Error("convert_to_aila_laine: too many leaf triangles for 31-bit links");
        for (uint32_t slot = leaf.first; slot < leaf.first + leaf.count; ++slot) {
            const uint32_t prim = bvh.prim_indices[slot];
            if (prim >= triangles.size())
                throw Error("convert_to_aila_laine: primitive index " + std::to_string(prim) + " out of range");
        }
        out.triangles.resize(offset + aila_laine::leaf_list_float4s(leaf.count));
        aila_laine::write_leaf_list(leaf, bvh.prim_indices.data(), triangles.data(), &out.triangles[offset]);
        ++out.leaf_count;
        out.triangle_refs += leaf.count;
        return ~static_cast<int32_t>(offset);
    };

    const BvhNode& root = bvh.nodes[0];
    if (root.is_leaf()) {
        out.root = emit_leaf(root);
        return out;
    }
    out.root = 0;

    // Depth-first (left before right), iteratively, so that inner nodes and
    // leaf lists both come out in the order a traversal meets them. Each
    // entry is a canonical node, the converted parent's slot that links to
    // it, and its depth in inner nodes (checked so that the traversal's
    // fixed stack cannot overflow).
    struct Pending {
        uint32_t canonical;
        int32_t parent;  // converted parent, -1 for the root
        int side;
        int depth;
    };
    std::vector<Pending> pending{{0, -1, 0, 1}};
    while (!pending.empty()) {
        const Pending p = pending.back();
        pending.pop_back();
        const BvhNode& node = bvh.nodes[p.canonical];
        if (node.is_leaf()) {
            out.nodes[static_cast<size_t>(p.parent)].link[p.side] = emit_leaf(node);
            continue;
        }
        if (p.depth > kBvhMaxDepth) throw Error("convert_to_aila_laine: BVH deeper than kBvhMaxDepth");
        if (out.nodes.size() >= kMaxLink) throw Error("convert_to_aila_laine: too many nodes for 31-bit links");
        const uint32_t left = node.first;
        // Children come after their parent in the canonical depth-first order;
        // requiring it also rules out cycles in a malformed BVH.
        if (left <= p.canonical || size_t{left} + 1 >= canonical_count)
            throw Error("convert_to_aila_laine: child link out of range");

        const auto index = static_cast<int32_t>(out.nodes.size());
        if (p.parent >= 0) out.nodes[static_cast<size_t>(p.parent)].link[p.side] = index;
        out.nodes.emplace_back();  // value-initialised: links and padding 0
        AilaLaineNode& converted = out.nodes.back();
        aila_laine::set_child_box(converted, 0, bvh.nodes[left].bounds);
        aila_laine::set_child_box(converted, 1, bvh.nodes[left + 1].bounds);
        pending.push_back({left + 1, index, 1, p.depth + 1});
        pending.push_back({left, index, 0, p.depth + 1});
    }
    return out;
}

}  // namespace rf
