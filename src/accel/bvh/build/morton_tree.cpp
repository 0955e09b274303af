// Morton codes and the raw-tree emitter shared by the LBVH, HLBVH2 and PLOC
// builders (see morton_tree.h).
#include "accel/bvh/build/morton_tree.h"

#include <algorithm>
#include <bit>
#include <unordered_map>

#include "accel/bvh/build/morton_code.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::morton {
namespace {

constexpr uint32_t kGrain = 16 * 1024;
constexpr uint32_t kParallelEmitCount = 4096;  // primitives per subtree to emit as its own task

inline Box3f triangle_box(const Triangle& t) {
    Box3f b;
    b.lo = Vec3f(std::min(t.v0.x, std::min(t.v1.x, t.v2.x)), std::min(t.v0.y, std::min(t.v1.y, t.v2.y)),
                 std::min(t.v0.z, std::min(t.v1.z, t.v2.z)));
    b.hi = Vec3f(std::max(t.v0.x, std::max(t.v1.x, t.v2.x)), std::max(t.v0.y, std::max(t.v1.y, t.v2.y)),
                 std::max(t.v0.z, std::max(t.v1.z, t.v2.z)));
    return b;
}
inline Vec3f box_center(const Box3f& b) { return (b.lo + b.hi) * 0.5f; }

Box3f centroid_bounds(std::span<const Triangle> triangles) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    return parallel::reduce(
        0u, n, kGrain, Box3f{},
        [&](uint32_t lo, uint32_t hi, Box3f acc) {
            for (uint32_t i = lo; i != hi; ++i) {
                const Vec3f c = box_center(triangle_box(triangles[i]));
                acc = box_union(acc, Box3f{c, c});
            }
            return acc;
        },
        [](Box3f a, const Box3f& b) { return box_union(a, b); });
}

template <class Key>
void codes_impl(std::span<const Triangle> triangles, std::vector<Key>& keys, std::vector<uint32_t>& order) {
    const uint32_t n = checked_index_count("Morton BVH primitive count", triangles.size());
    if (n >= kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
    budgeted_resize(keys, n, "Morton BVH build: Morton codes");
    budgeted_resize(order, n, "Morton BVH build: primitive order");
    if (n == 0) return;
    const MortonQuantizer quantizer(centroid_bounds(triangles), sizeof(Key) == 4 ? 10 : 21);
    parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) {
            const Vec3f c = box_center(triangle_box(triangles[i]));
            if constexpr (sizeof(Key) == 4) {
                keys[i] = quantizer.code30(c);
            } else {
                keys[i] = quantizer.code63(c);
            }
            order[i] = i;
        }
    });
}

}  // namespace

void compute_morton_codes(std::span<const Triangle> triangles, std::vector<uint32_t>& keys,
                          std::vector<uint32_t>& order) {
    codes_impl(triangles, keys, order);
}
void compute_morton_codes(std::span<const Triangle> triangles, std::vector<uint64_t>& keys,
                          std::vector<uint32_t>& order) {
    codes_impl(triangles, keys, order);
}

int balanced_levels(uint32_t count, uint32_t leaf_size) {
    const uint32_t leaves = (count + leaf_size - 1) / leaf_size;
    return leaves <= 1 ? 0 : std::bit_width(leaves - 1);
}

RawTree::RawTree(std::span<const Triangle> tris, const BuildOptions& options)
    : triangles(tris),
      max_leaf_size_(static_cast<uint32_t>(std::clamp(options.max_leaf_size, 1, 255))),
      traversal_cost_(options.traversal_cost),
      intersection_cost_(options.intersection_cost) {}

void RawTree::set_order(std::vector<uint32_t>&& sorted) {
    order = std::move(sorted);
    const uint32_t n = size();
    budgeted_resize(boxes, n, "Morton BVH build: sorted boxes");
    parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) boxes[i] = triangle_box(triangles[order[i]]);
    });
}

void RawTree::enable_leaf_runs() { budgeted_resize(leaf_run_, size(), "Morton BVH build: leaf runs"); }

Box3f RawTree::bounds(uint32_t ref) const {
    if (!is_leaf_ref(ref)) return nodes[ref].box;
    const uint32_t first = ref & ~kLeafRef;
    Box3f box = boxes[first];
    if (!leaf_run_.empty()) {
        for (uint32_t i = 1; i < leaf_run_[first]; ++i) box = box_union(box, boxes[first + i]);
    }
    return box;
}

uint32_t RawTree::count(uint32_t ref) const {
    if (!is_leaf_ref(ref)) return nodes[ref].count;
    return leaf_run_.empty() ? 1u : leaf_run_[ref & ~kLeafRef];
}

RawTree::Info RawTree::info(uint32_t ref) const {
    if (is_leaf_ref(ref)) {
        const Box3f box = bounds(ref);
        const uint32_t n = count(ref);
        return {box, n, intersection_cost_ * half_area(box) * static_cast<float>(n), 1, 0};
    }
    const RawNode& node = nodes[ref];
    return {node.box, node.count, node.cost, node.out_size, node.height};
}

void RawTree::finalize(uint32_t index, uint32_t left, uint32_t right) {
    const Info a = info(left), b = info(right);
    RawNode& node = nodes[index];
    node.child[0] = left;
    node.child[1] = right;
    node.box = box_union(a.box, b.box);
    node.count = a.count + b.count;
    const float area = half_area(node.box);
    const float split_cost = traversal_cost_ * area + a.cost + b.cost;
    node.flags = 0;
    if (node.count <= max_leaf_size_) {
        // Karras 2013-style collapse: one leaf where the SAH prefers it.
        const float leaf_cost = intersection_cost_ * area * static_cast<float>(node.count);
        if (!(leaf_cost > split_cost)) {
            node.cost = leaf_cost;
            node.out_size = 1;
            node.height = 0;
            node.flags = kCollapsed;
            return;
        }
    }
    node.cost = split_cost;
    node.out_size = 1 + a.out_size + b.out_size;
    node.height = static_cast<uint16_t>(std::min<uint32_t>(1 + std::max(a.height, b.height), 0xffff));
}

// Nodes of the balanced halving of `count` primitives: 2 * leaves - 1, with
// leaves(m) = 1 for m <= L, else leaves(ceil(m/2)) + leaves(floor(m/2)).
// Only two distinct sizes occur per level, so a memo keeps it logarithmic.
uint32_t RawTree::balanced_size(uint32_t count) const {
    std::unordered_map<uint32_t, uint32_t> memo;
    auto leaves = [&](auto&& self, uint32_t m) -> uint32_t {
        if (m <= max_leaf_size_) return 1;
        if (auto it = memo.find(m); it != memo.end()) return it->second;
        const uint32_t r = self(self, m - m / 2) + self(self, m / 2);
        memo.emplace(m, r);
        return r;
    };
    return 2 * leaves(leaves, count) - 1;
}

// Called for inner node `index` at `depth` whose emitted height would end
// below kBvhMaxDepth; the caller guarantees that a balanced halving of it
// fits. Keeps the node while both children can still be placed one level
// down (rebuilding them if needed), so that only the offending subtrees are
// rebuilt, as deep as possible.
void RawTree::plan_depth(uint32_t index, int depth) {
    RawNode& node = nodes[index];
    const int room = kBvhMaxDepth - depth;  // levels available below this node
    bool keep = room >= 1;
    for (uint32_t c : node.child) {
        if (!is_leaf_ref(c) && balanced_levels(nodes[c].count, max_leaf_size_) > room - 1) keep = false;
    }
    if (!keep) {
        node.flags |= kRebuild;
        node.out_size = balanced_size(node.count);
        node.height = static_cast<uint16_t>(balanced_levels(node.count, max_leaf_size_));
        return;
    }
    uint32_t out_size = 1, height = 0;
    for (uint32_t c : node.child) {
        if (!is_leaf_ref(c)) {
            RawNode& child = nodes[c];
            if (!(child.flags & kCollapsed) && depth + 1 + child.height > kBvhMaxDepth) plan_depth(c, depth + 1);
            out_size += child.out_size;
            height = std::max<uint32_t>(height, child.height + 1u);
        } else {
            out_size += 1;
            height = std::max<uint32_t>(height, 1u);
        }
    }
    node.out_size = out_size;
    node.height = static_cast<uint16_t>(height);
}

Bvh RawTree::emit(uint32_t root) {
    Bvh bvh;
    const uint32_t n = size();
    if (n == 0) return bvh;
    if (!is_leaf_ref(root)) {
        RawNode& node = nodes[root];
        if (!(node.flags & kCollapsed) && node.height > kBvhMaxDepth) plan_depth(root, 0);
    }
    const uint32_t node_count = is_leaf_ref(root) ? 1u : nodes[root].out_size;
    budgeted_resize(bvh.nodes, node_count, "BVH nodes");
    budgeted_resize(bvh.prim_indices, n, "BVH primitive indices");
    emit_node(bvh, root, 0, 1, 0);
    return bvh;
}

// Writes the subtree `ref` at bvh.nodes[at], its children pair (if any) at
// child_base and its primitives from leaf slot `slot` on.
void RawTree::emit_node(Bvh& bvh, uint32_t ref, uint32_t at, uint32_t child_base, uint32_t slot) const {
    BvhNode& out = bvh.nodes[at];
    if (is_leaf_ref(ref)) {
        const uint32_t first = ref & ~kLeafRef, n = count(ref);
        out.bounds = bounds(ref);
        out.first = slot;
        out.count = n;
        for (uint32_t i = 0; i < n; ++i) bvh.prim_indices[slot + i] = order[first + i];
        return;
    }
    const RawNode& node = nodes[ref];
    if (node.flags & kCollapsed) {
        // At most max_leaf_size (<= 255) primitives, so the walk's stack fits on the call stack.
        out.bounds = node.box;
        out.first = slot;
        out.count = node.count;
        uint32_t stack[256];
        uint32_t top = 0, next = slot;
        stack[top++] = ref;
        while (top > 0) {
            const uint32_t r = stack[--top];
            if (is_leaf_ref(r)) {
                const uint32_t first = r & ~kLeafRef, n = count(r);
                for (uint32_t i = 0; i < n; ++i) bvh.prim_indices[next++] = order[first + i];
            } else {
                stack[top++] = nodes[r].child[1];
                stack[top++] = nodes[r].child[0];
            }
        }
        return;
    }
    if (node.flags & kRebuild) {
        std::vector<uint32_t> positions;
        positions.reserve(node.count);
        gather_positions(ref, positions);
        emit_balanced(bvh, positions, at, child_base, slot);
        return;
    }
    out.bounds = node.box;
    out.first = child_base;
    out.count = 0;
    const uint32_t left = node.child[0], right = node.child[1];
    const uint32_t left_size = is_leaf_ref(left) ? 1u : nodes[left].out_size;
    const uint32_t right_base = child_base + 2 + (left_size - 1);
    const uint32_t right_slot = slot + count(left);
    if (node.count > kParallelEmitCount) {
        parallel::invoke([&] { emit_node(bvh, left, child_base, child_base + 2, slot); },
                         [&] { emit_node(bvh, right, child_base + 1, right_base, right_slot); });
    } else {
        emit_node(bvh, left, child_base, child_base + 2, slot);
        emit_node(bvh, right, child_base + 1, right_base, right_slot);
    }
}

// Sorted positions of the primitives below `ref`, left to right (an explicit
// stack: a subtree being rebuilt may be a chain far deeper than the call stack).
void RawTree::gather_positions(uint32_t ref, std::vector<uint32_t>& positions) const {
    std::vector<uint32_t> stack{ref};
    while (!stack.empty()) {
        const uint32_t r = stack.back();
        stack.pop_back();
        if (is_leaf_ref(r)) {
            const uint32_t first = r & ~kLeafRef, n = count(r);
            for (uint32_t i = 0; i < n; ++i) positions.push_back(first + i);
        } else {
            stack.push_back(nodes[r].child[1]);
            stack.push_back(nodes[r].child[0]);
        }
    }
}

// The balanced halving of `positions` (left half rounded up), depth-first.
Box3f RawTree::emit_balanced(Bvh& bvh, std::span<const uint32_t> positions, uint32_t at, uint32_t child_base,
                             uint32_t slot) const {
    const uint32_t n = static_cast<uint32_t>(positions.size());
    BvhNode& out = bvh.nodes[at];
    if (n <= max_leaf_size_) {
        Box3f box = boxes[positions[0]];
        for (uint32_t i = 0; i < n; ++i) {
            box = box_union(box, boxes[positions[i]]);
            bvh.prim_indices[slot + i] = order[positions[i]];
        }
        out.bounds = box;
        out.first = slot;
        out.count = n;
        return box;
    }
    const uint32_t half = n - n / 2;
    const uint32_t right_base = child_base + 2 + (balanced_size(half) - 1);
    const Box3f a = emit_balanced(bvh, positions.first(half), child_base, child_base + 2, slot);
    const Box3f b = emit_balanced(bvh, positions.subspan(half), child_base + 1, right_base, slot + half);
    out.bounds = box_union(a, b);
    out.first = child_base;
    out.count = 0;
    return out.bounds;
}

}  // namespace rf::morton
