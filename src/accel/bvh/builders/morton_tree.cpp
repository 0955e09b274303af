// Morton codes and the raw-tree emitter shared by the LBVH, HLBVH2 and PLOC
// builders (see morton_tree.h). Arrays the builders fill completely start
// uninitialised (morton_buffer.h); hot node operations are inline in the header.
#include "accel/bvh/builders/morton_tree.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstring>
#include <unordered_map>

#include "accel/bvh/builders/morton_code.h"
#include "accel/bvh/builders/morton_radix_sort.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::morton {
namespace {

constexpr uint32_t kGrain = 16 * 1024;
constexpr uint32_t kParallelEmitCount = 4096;  // primitives per subtree to emit as its own task

inline Vec3f box_center(const Box3f& b) { return (b.lo + b.hi) * 0.5f; }

// Centroid bounds of the triangles (box centres); writes each triangle's box
// to boxes[i] on the way when boxes is not null.
Box3f centroid_bounds(std::span<const Triangle> triangles, Box3f* boxes) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    return parallel::reduce(
        0u, n, kGrain, Box3f{},
        [&](uint32_t lo, uint32_t hi, Box3f acc) {
            for (uint32_t i = lo; i != hi; ++i) {
                const Box3f b = triangle_box(triangles[i]);
                if (boxes) boxes[i] = b;
                const Vec3f c = box_center(b);
                acc = box_union(acc, Box3f{c, c});
            }
            return acc;
        },
        [](Box3f a, const Box3f& b) { return box_union(a, b); });
}

template <class Key>
Key morton_code(const MortonQuantizer& quantizer, const Box3f& box) {
    if constexpr (sizeof(Key) == 4) {
        return quantizer.code30(box_center(box));
    } else {
        return quantizer.code63(box_center(box));
    }
}

template <class Key>
void codes_impl(std::span<const Triangle> triangles, std::vector<Key>& keys, std::vector<uint32_t>& order) {
    const uint32_t n = checked_index_count("Morton BVH primitive count", triangles.size());
    if (n >= kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
    budgeted_resize(keys, n, "Morton BVH build: Morton codes");
    budgeted_resize(order, n, "Morton BVH build: primitive order");
    if (n == 0) return;
    const MortonQuantizer quantizer(centroid_bounds(triangles, nullptr), sizeof(Key) == 4 ? 10 : 21);
    parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) {
            keys[i] = morton_code<Key>(quantizer, triangle_box(triangles[i]));
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

// One pass over the triangles computes their boxes and the centroid bounds,
// a second their codes (from the boxes), then the sort, and one gather puts
// the boxes into sorted order. 30-bit codes are sorted packed above their
// triangle index in one 64-bit word.
template <class Key>
void RawTree::sort_impl(Buffer<Key>& keys, double* code_ms) {
    const auto start = std::chrono::steady_clock::now();
    auto codes_done = [&] {
        if (code_ms) *code_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    };
    const uint32_t n = checked_index_count("Morton BVH primitive count", triangles.size());
    if (n >= kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
    order.clear();
    boxes.clear();
    keys.clear();
    if (n == 0) return;
    Buffer<Box3f> triangle_boxes(n, "Morton BVH build: triangle boxes");
    const MortonQuantizer quantizer(centroid_bounds(triangles, triangle_boxes.data()), sizeof(Key) == 4 ? 10 : 21);
    budgeted_resize(order, n, "Morton BVH build: primitive order");
    boxes.allocate(n, "Morton BVH build: sorted boxes");
    keys.allocate(n, "Morton BVH build: Morton codes");
    if constexpr (sizeof(Key) == 4) {
        Buffer<uint64_t> items(n, "Morton BVH build: sort items"), tmp(n, "Morton BVH build: sort items");
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                items[i] = (uint64_t{morton_code<uint32_t>(quantizer, triangle_boxes[i])} << 32) | i;
            }
        });
        codes_done();
        const uint64_t* sorted = radix_sort_packed(items.data(), tmp.data(), n, 32, 30);
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                const uint64_t item = sorted[i];
                const uint32_t t = static_cast<uint32_t>(item);
                keys[i] = static_cast<uint32_t>(item >> 32);
                order[i] = t;
                boxes[i] = triangle_boxes[t];
            }
        });
    } else {
        Buffer<uint64_t> key_tmp(n, "Morton BVH build: sort keys");
        Buffer<uint32_t> values(n, "Morton BVH build: sort values");
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                keys[i] = morton_code<uint64_t>(quantizer, triangle_boxes[i]);
                order[i] = i;
            }
        });
        codes_done();
        if (radix_sort_pairs(keys.data(), order.data(), key_tmp.data(), values.data(), n, 63)) {
            keys.swap(key_tmp);
            std::memcpy(order.data(), values.data(), size_t{n} * sizeof(uint32_t));
        }
        parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) boxes[i] = triangle_boxes[order[i]];
        });
    }
}

void RawTree::sort_by_morton_codes(Buffer<uint32_t>& keys, double* code_ms) { sort_impl(keys, code_ms); }
void RawTree::sort_by_morton_codes(Buffer<uint64_t>& keys, double* code_ms) { sort_impl(keys, code_ms); }

int balanced_levels(uint32_t count, uint32_t leaf_size) {
    const uint32_t leaves = (count + leaf_size - 1) / leaf_size;
    return leaves <= 1 ? 0 : std::bit_width(leaves - 1);
}

RawTree::RawTree(std::span<const Triangle> tris, const BvhBuildConfig& config)
    : triangles(tris),
      max_leaf_size_(static_cast<uint32_t>(std::clamp(config.max_leaf_size, 1, 255))),
      costs_{config.sah.traversal, config.sah.intersection, max_leaf_size_} {}

void RawTree::set_order(std::vector<uint32_t>&& sorted) {
    order = std::move(sorted);
    const uint32_t n = size();
    boxes.allocate(n, "Morton BVH build: sorted boxes");
    parallel::for_range(0u, n, kGrain, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i != hi; ++i) boxes[i] = triangle_box(triangles[order[i]]);
    });
}

// Every leaf run's size is set by the builder before it is read.
void RawTree::enable_leaf_runs() {
    leaf_run_.allocate(size(), "Morton BVH build: leaf runs");
    leaf_runs_ = true;
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

Bvh RawTree::emit(uint32_t root) { return emit_impl(root, false); }
Bvh RawTree::emit_in_order(uint32_t root) { return emit_impl(root, true); }

Bvh RawTree::emit_impl(uint32_t root, bool in_order) {
    Bvh bvh;
    const uint32_t n = size();
    if (n == 0) return bvh;
    if (!is_leaf_ref(root)) {
        RawNode& node = nodes[root];
        if (!(node.flags & kCollapsed) && node.height > kBvhMaxDepth) plan_depth(root, 0);
    }
    const uint32_t node_count = is_leaf_ref(root) ? 1u : nodes[root].out_size;
    budgeted_resize(bvh.nodes, node_count, "BVH nodes");
    if (in_order) {
        emit_node<true>(bvh, root, 0, 1, 0);
        bvh.prim_indices = std::move(order);
        order.clear();
    } else {
        budgeted_resize(bvh.prim_indices, n, "BVH primitive indices");
        emit_node<false>(bvh, root, 0, 1, 0);
    }
    return bvh;
}

// Writes the subtree `ref` at bvh.nodes[at], its children pair (if any) at
// child_base and its primitives from leaf slot `slot` on (kInOrder: slot is
// the sorted position of the subtree's first primitive, and the primitive
// slots are written by the caller).
template <bool kInOrder>
void RawTree::emit_node(Bvh& bvh, uint32_t ref, uint32_t at, uint32_t child_base, uint32_t slot) const {
    BvhNode& out = bvh.nodes[at];
    if (is_leaf_ref(ref)) {
        const uint32_t first = ref & ~kLeafRef, n = count(ref);
        out.bounds = bounds(ref);
        out.first = slot;
        out.count = n;
        if constexpr (!kInOrder) {
            for (uint32_t i = 0; i < n; ++i) bvh.prim_indices[slot + i] = order[first + i];
        }
        return;
    }
    const RawNode& node = nodes[ref];
    if (node.flags & kCollapsed) {
        out.bounds = node.box;
        out.first = slot;
        out.count = node.count;
        if constexpr (!kInOrder) {
            // At most max_leaf_size (<= 255) primitives, so the walk's stack fits on the call stack.
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
        }
        return;
    }
    if (node.flags & kRebuild) {
        std::vector<uint32_t> positions;
        positions.reserve(node.count);
        gather_positions(ref, positions);
        emit_balanced<kInOrder>(bvh, positions, at, child_base, slot);
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
        parallel::invoke([&] { emit_node<kInOrder>(bvh, left, child_base, child_base + 2, slot); },
                         [&] { emit_node<kInOrder>(bvh, right, child_base + 1, right_base, right_slot); });
    } else {
        emit_node<kInOrder>(bvh, left, child_base, child_base + 2, slot);
        emit_node<kInOrder>(bvh, right, child_base + 1, right_base, right_slot);
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
template <bool kInOrder>
Box3f RawTree::emit_balanced(Bvh& bvh, std::span<const uint32_t> positions, uint32_t at, uint32_t child_base,
                             uint32_t slot) const {
    const uint32_t n = static_cast<uint32_t>(positions.size());
    BvhNode& out = bvh.nodes[at];
    if (n <= max_leaf_size_) {
        Box3f box = boxes[positions[0]];
        for (uint32_t i = 0; i < n; ++i) {
            box = box_union(box, boxes[positions[i]]);
            if constexpr (!kInOrder) bvh.prim_indices[slot + i] = order[positions[i]];
        }
        out.bounds = box;
        out.first = slot;
        out.count = n;
        return box;
    }
    const uint32_t half = n - n / 2;
    const uint32_t right_base = child_base + 2 + (balanced_size(half) - 1);
    const Box3f a = emit_balanced<kInOrder>(bvh, positions.first(half), child_base, child_base + 2, slot);
    const Box3f b = emit_balanced<kInOrder>(bvh, positions.subspan(half), child_base + 1, right_base, slot + half);
    out.bounds = box_union(a, b);
    out.first = child_base;
    out.count = 0;
    return out.bounds;
}

}  // namespace rf::morton
