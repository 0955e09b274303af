// Binary-to-wide BVH collapse by the cost-optimal dynamic programme of Ylitie,
// Karras and Laine 2017 ("Efficient incoherent ray traversal on GPUs through
// compressed wide BVHs", section 3), adapted to this CPU layout: every binary
// subtree is assigned, bottom-up, the cheapest way to cover it with up to N
// slots of its parent wide node, each slot a wide node or a leaf of 4-triangle
// packs, under an SAH cost (node tests and pack tests weighted by box area).
// Compared with greedy largest-area opening (Wald, Benthin and Boulos 2008)
// it fills nodes better and picks leaf sizes by cost: 8-12% fewer
// instructions per ray on Sponza.
//
// Implementation: one bottom-up pass computes the cost tables (they travel
// up the recursion by value, costs only) and stores each node's reference
// count and choices in an uninitialised array. A second pass, over the
// chosen wide tree only, counts the wide nodes and packs under every slot.
// With the counts known, the output arrays get their final sizes and the
// wide nodes (depth-first, as a sequential top-down pass would lay them out)
// and the leaves' triangle packs are written by parallel tasks. Every
// decision and position depends only on the subtree, so the result is the
// same for any thread count.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>


#include "accel/bvh/layout/wide_bvh.h"
#include "core/huge_pages.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

template <int N>
class Collapser {
public:
    Collapser(const Bvh& bvh, const std::vector<Triangle>& triangles) : bvh_(bvh), triangles_(triangles) {}

    WideBvh<N> run() {
        WideBvh<N> out;
        if (bvh_.nodes.empty()) return out;
        // Default-initialised: every reachable entry is written before it is read.
        info_.reset(new NodeInfo[bvh_.nodes.size()]);
        (void)solve(0, 0);
        const Box3f& root = bvh_.nodes[0].bounds;
        for (int axis = 0; axis < 3; ++axis) {
            out.coord_scale = std::fmax(out.coord_scale, std::fmax(std::fabs(root.lo[axis]), std::fabs(root.hi[axis])));
        }
        // Only a root with more references than one pack holds becomes a
        // wide node; a smaller scene gets a one-slot root holding a leaf.
        const bool expand = !bvh_.nodes[0].is_leaf() && info_[0].refs > uint32_t(kTrianglePackWidth);
        const Counts totals = expand ? count_wide(0, 0) : count_slot(0, 0);
        if (totals.max_refs > kMaxLeafRefs) throw leaf_size_error(totals.max_refs);
        if (totals.packs > (1u << 27) + kWideMaxPacksPerLeaf) throw Error("wide BVH collapse: too many triangle packs");
        const uint32_t node_count = (expand ? 0u : 1u) + totals.wides;
        out_ = &out;
        parallel::invoke([&] { sized(out.nodes, node_count); }, [&] { sized(out.packs, totals.packs); });
        out.leaf_count = totals.leaves;
        if (expand) {
            build_node(0, 0, 1, 0);
        } else {
            // The root is itself a leaf (or covered by one wide node slot).
            clear_node(0);
            set_root_slot();
        }
        if (too_many_packs_.load(std::memory_order_relaxed)) throw Error("wide BVH collapse: too many triangle packs");
        return out;
    }

private:
    // What covering a binary subtree the chosen way produces.
    struct Counts {
        uint32_t packs;     // triangle packs
        uint32_t wides;     // wide nodes
        uint32_t leaves;    // wide leaves
        uint32_t max_refs;  // references of the largest wide leaf
        Counts& operator+=(const Counts& o) {
            packs += o.packs;
            wides += o.wides;
            leaves += o.leaves;
            max_refs = std::max(max_refs, o.max_refs);
            return *this;
        }
    };
    // SAH costs of a binary subtree: slots[i - 1] covered by at most i
    // slots; as_node as a wide node of its own (the root's shape when it is
    // expanded). Costs only: what a choice produces is counted afterwards,
    // for the chosen tree alone.
    struct Table {
        float slots[N];
        float as_node;
    };
    // Per binary node: the subtree's triangle references, what it produces
    // as one slot (set by the counting pass, for slots of the chosen tree
    // only), and the choices of the cost-optimal assignment.
    // split[i - 1] (i >= 2): how at most i slots are shared, left | right <<
    // 4, 0 = one slot; split[0]: as one slot, wide node (bit 0) or leaf, and
    // as a wide node the slots given to the left child (bits 1 to 4).
    struct NodeInfo {
        uint32_t refs;
        uint32_t packs;  // as one slot
        uint32_t wides;  // as one slot
        uint8_t split[N];
    };

    static constexpr int kParallelDepth = 8;          // binary levels solved as parallel tasks
    static constexpr int kMaxRecursionDepth = 512;    // then explicit stacks
    static constexpr uint32_t kParallelPacks = 2048;  // packs under a wide node to fill its children in parallel
    static constexpr int kParallelCountDepth = 3;     // wide levels counted as parallel tasks
    static constexpr uint32_t kMaxLeafRefs = kWideMaxPacksPerLeaf * kTrianglePackWidth;

    // Resizes a fresh output array. Large ones ask Linux for transparent huge
    // pages first: the arrays are written once, end to end, and with 4 KiB
    // pages the page faults cost about as much as filling them.
    template <class T>
    static void sized(std::vector<T>& v, size_t count) {
        v.reserve(count);
        hint_huge_pages(v.data(), count * sizeof(T));
        v.resize(count);
    }

    static uint32_t pack_count(uint32_t refs) { return (refs + kTrianglePackWidth - 1) / kTrianglePackWidth; }
    bool inner(uint32_t b) const { return (info_[b].split[0] & 1u) != 0; }
    int node_split(uint32_t b) const { return info_[b].split[0] >> 1; }

    static Error leaf_size_error(uint32_t refs) {
        return Error("wide BVH collapse: a leaf holds " + std::to_string(refs) + " triangles (1 to " +
                     std::to_string(kWideMaxPacksPerLeaf * kTrianglePackWidth) + " supported)");
    }

    // Cost-optimal assignment (Ylitie, Karras and Laine 2017, section 3):
    // slots[i - 1].cost is the least SAH cost of covering binary subtree n
    // with at most i wide-node slots, each slot a leaf of packs or a wide
    // node. A wide node costs kNodeCost times its box area (one SIMD test of
    // all N child boxes, whatever their number), a leaf kPackCost per pack
    // times its area. Children first; the choices are kept so the wide tree
    // can be read back top-down.
    Table solve(uint32_t n, int depth) {
        const BvhNode& node = bvh_.nodes[n];
        if (node.is_leaf()) return leaf_table(n);
        if (depth >= kParallelDepth) return solve_recursive(n, depth);
        Table left, right;
        parallel::invoke([&] { left = solve(node.first, depth + 1); },
                         [&] { right = solve(node.first + 1, depth + 1); });
        return combine(n, left, right);
    }

    // Plain recursion for trees of ordinary depth (every builder keeps
    // within kBvhMaxDepth); deeper ones continue with explicit stacks.
    Table solve_recursive(uint32_t n, int depth) {
        const BvhNode& node = bvh_.nodes[n];
        if (node.is_leaf()) return leaf_table(n);
        if (depth >= kMaxRecursionDepth) return solve_serial(n);
        const Table left = solve_recursive(node.first, depth + 1);
        const Table right = solve_recursive(node.first + 1, depth + 1);
        return combine(n, left, right);
    }

    // Post-order over subtree `root` with explicit stacks (no depth limit).
    Table solve_serial(uint32_t root) {
        struct Frame {
            uint32_t node;
            bool expanded;
        };
        std::vector<Frame> stack;
        std::vector<Table> values;
        stack.reserve(2 * kBvhMaxDepth + 2);
        values.reserve(kBvhMaxDepth + 2);
        stack.push_back({root, false});
        while (!stack.empty()) {
            const Frame frame = stack.back();
            stack.pop_back();
            const BvhNode& node = bvh_.nodes[frame.node];
            if (node.is_leaf()) {
                values.push_back(leaf_table(frame.node));
            } else if (!frame.expanded) {
                stack.push_back({frame.node, true});
                stack.push_back({node.first + 1, false});
                stack.push_back({node.first, false});
            } else {
                const Table right = values.back();
                values.pop_back();
                values.back() = combine(frame.node, values.back(), right);
            }
        }
        return values.back();
    }

    Table leaf_table(uint32_t n) {
        const BvhNode& node = bvh_.nodes[n];
        NodeInfo& info = info_[n];
        info.refs = node.count;
        for (int i = 0; i < N; ++i) info.split[i] = 0;
        const float leaf = node.bounds.surface_area() * kPackCost * float(pack_count(node.count));
        Table table;
        for (int i = 0; i < N; ++i) table.slots[i] = leaf;
        table.as_node = leaf;  // never used: a binary leaf is never expanded
        return table;
    }

    Table combine(uint32_t n, const Table& left, const Table& right) {
        constexpr float kInf = std::numeric_limits<float>::infinity();
        const BvhNode& node = bvh_.nodes[n];
        NodeInfo& info = info_[n];
        const uint32_t refs = info_[node.first].refs + info_[node.first + 1].refs;
        const float area = node.bounds.surface_area();
        const uint32_t packs = pack_count(refs);
        // dist[j - 1]: both children with at most j slots between them, the
        // left child getting dist_k[j - 1] of them (the first best k).
        float dist[N];
        int dist_k[N];
        dist[0] = kInf;
        dist_k[0] = 0;
        for (int j = 2; j <= N; ++j) {
            float best = kInf;
            int best_k = 1;
            for (int k = 1; k < j; ++k) {
                const float c = left.slots[k - 1] + right.slots[j - k - 1];
                const bool better = c < best;
                best = better ? c : best;
                best_k = better ? k : best_k;
            }
            dist[j - 1] = best;
            dist_k[j - 1] = best_k;
        }
        Table table;
        table.as_node = area * kNodeCost + dist[N - 1];
        const float as_leaf = packs <= kMaxLeafPacks ? area * kPackCost * float(packs) : kInf;
        const bool is_inner = table.as_node < as_leaf;
        table.slots[0] = is_inner ? table.as_node : as_leaf;
        info.refs = refs;
        info.split[0] = uint8_t((is_inner ? 1u : 0u) | (unsigned(dist_k[N - 1]) << 1));
        uint8_t split = 0;
        for (int i = 2; i <= N; ++i) {
            const bool better = dist[i - 1] < table.slots[i - 2];
            table.slots[i - 1] = better ? dist[i - 1] : table.slots[i - 2];
            const int a = dist_k[i - 1];
            split = better ? uint8_t(a | ((i - a) << 4)) : split;
            info.split[i - 1] = split;
        }
        return table;
    }

    // Counts what slot b produces under the chosen assignment and records
    // its packs and wide nodes for the layout.
    Counts count_slot(uint32_t b, int depth) {
        NodeInfo& info = info_[b];
        const Counts c = inner(b) ? count_wide(b, depth) : Counts{pack_count(info.refs), 0, 1, info.refs};
        info.packs = c.packs;
        info.wides = c.wides;
        return c;
    }

    // Counts binary node b expanded into a wide node: the node and its slots.
    Counts count_wide(uint32_t b, int depth) {
        uint32_t slots[N];
        const int used = node_slots(b, slots);
        Counts child[N];
        auto count = [&](int c) { child[c] = count_slot(slots[c], depth + 1); };
        if (depth < kParallelCountDepth) {
            parallel::for_range(0, used, 1, [&](int lo, int hi) {
                for (int c = lo; c < hi; ++c) count(c);
            });
        } else {
            for (int c = 0; c < used; ++c) count(c);
        }
        Counts total{0, 1, 0, 0};
        for (int c = 0; c < used; ++c) total += child[c];
        return total;
    }

    // The slots of binary node b as a wide node, left to right; returns their number.
    int node_slots(uint32_t b, uint32_t* slots) const {
        int used = 0;
        const uint32_t left = bvh_.nodes[b].first;
        const int k = node_split(b);
        gather_slots(left, k, slots, used);
        gather_slots(left + 1, N - k, slots, used);
        return used;
    }

    // Appends the slots that cover binary subtree n with at most i slots.
    void gather_slots(uint32_t n, int i, uint32_t* slots, int& used) const {
        const uint8_t s = i >= 2 ? info_[n].split[i - 1] : uint8_t(0);
        if (s == 0) {
            slots[used++] = n;
            return;
        }
        gather_slots(bvh_.nodes[n].first, s & 15, slots, used);
        gather_slots(bvh_.nodes[n].first + 1, s >> 4, slots, used);
    }

    void clear_node(uint32_t w) {
        WideNode<N>& node = out_->nodes[w];
        for (int c = 0; c < N; ++c) {
            for (int axis = 0; axis < 3; ++axis) {
                node.bounds[2 * axis][c] = std::numeric_limits<float>::infinity();
                node.bounds[2 * axis + 1][c] = -std::numeric_limits<float>::infinity();
            }
            node.child[c] = kWideEmptyRef;
        }
    }

    void set_box(uint32_t w, int c, uint32_t b) {
        const Box3f& box = bvh_.nodes[b].bounds;
        WideNode<N>& node = out_->nodes[w];
        node.bounds[0][c] = box.lo.x;
        node.bounds[1][c] = box.hi.x;
        node.bounds[2][c] = box.lo.y;
        node.bounds[3][c] = box.hi.y;
        node.bounds[4][c] = box.lo.z;
        node.bounds[5][c] = box.hi.z;
    }

    // The unexpanded root: slot 0 of wide node 0.
    void set_root_slot() {
        set_box(0, 0, 0);
        if (inner(0)) {
            out_->nodes[0].child[0] = 1;
            build_node(0, 1, 2, 0);
        } else {
            out_->nodes[0].child[0] = wide_make_leaf(0, info_[0].packs);
            pack_leaf(0, 0);
        }
    }

    // Fills wide node w with the slots of binary node b. Its descendants are
    // laid out depth-first from wide node next_node and pack next_pack on,
    // as a sequential top-down pass would place them.
    void build_node(uint32_t b, uint32_t w, uint32_t next_node, uint32_t next_pack) {
        uint32_t slots[N];
        const int used = node_slots(b, slots);
        clear_node(w);
        uint32_t child_node[N], child_pack[N];
        const uint32_t first_pack = next_pack;
        for (int c = 0; c < used; ++c) {
            const uint32_t s = slots[c];
            set_box(w, c, s);
            child_pack[c] = next_pack;
            if (inner(s)) {
                child_node[c] = next_node;
                out_->nodes[w].child[c] = next_node;
                next_node += info_[s].wides;
            } else {
                out_->nodes[w].child[c] = wide_make_leaf(next_pack, info_[s].packs);
            }
            next_pack += info_[s].packs;
        }
        // The leaves' triangles are scattered: ask for all of them before
        // packing any, so that their fetches overlap.
        for (int c = 0; c < used; ++c) {
            if (!inner(slots[c])) prefetch_leaf(slots[c]);
        }
        auto fill = [&](int c) {
            const uint32_t s = slots[c];
            if (inner(s)) {
                build_node(s, child_node[c], child_node[c] + 1, child_pack[c]);
            } else {
                pack_leaf(s, child_pack[c]);
            }
        };
        if (next_pack - first_pack > kParallelPacks) {
            parallel::for_range(0, used, 1, [&](int lo, int hi) {
                for (int c = lo; c < hi; ++c) fill(c);
            });
        } else {
            for (int c = 0; c < used; ++c) fill(c);
        }
    }

    // The triangle references of binary subtree b, left to right, into
    // prims (at most kMaxLeafRefs, checked in run()); returns their number.
    uint32_t gather_prims(uint32_t b, uint32_t* prims) const {
        uint32_t count = 0;
        // At most 64 references, so at most 64 binary leaves: the
        // depth-first stack never holds more than 64 entries.
        uint32_t stack[kMaxLeafRefs + 2];
        int top = 0;
        stack[top++] = b;
        while (top > 0) {
            const BvhNode& node = bvh_.nodes[stack[--top]];
            if (node.is_leaf()) {
                for (uint32_t s = node.first; s < node.first + node.count; ++s) prims[count++] = bvh_.prim_indices[s];
            } else {
                stack[top++] = node.first + 1;
                stack[top++] = node.first;
            }
        }
        return count;
    }

    // Starts fetching the triangles of binary subtree b (a wide leaf).
    void prefetch_leaf(uint32_t b) const {
        uint32_t prims[kMaxLeafRefs];
        const uint32_t count = gather_prims(b, prims);
        for (uint32_t i = 0; i < count; ++i) {
            const Triangle& tri = triangles_[prims[i]];
            __builtin_prefetch(&tri.v0);
            __builtin_prefetch(&tri.v2.z);  // 36 bytes may span two lines
        }
    }

    // Gathers the references of binary subtree b (left to right) into packs
    // of four from pack `first` on.
    void pack_leaf(uint32_t b, uint32_t first) {
        if (first >= (1u << 27)) {
            too_many_packs_.store(true, std::memory_order_relaxed);
            return;
        }
        uint32_t prims[kMaxLeafRefs];
        const uint32_t count = gather_prims(b, prims);
        const uint32_t packs = pack_count(count);
        const float nan = std::numeric_limits<float>::quiet_NaN();
        for (uint32_t p = 0; p < packs; ++p) {
            TrianglePack& pack = out_->packs[first + p];
            for (int lane = 0; lane < kTrianglePackWidth; ++lane) {
                const size_t slot = size_t(p) * kTrianglePackWidth + size_t(lane);
                pack.prim[lane] = slot < count ? prims[slot] : kInvalidId;
                bool usable = slot < count;
                Triangle tri{};
                if (usable) {
                    tri = triangles_[prims[slot]];
                    // Zero-area triangles never hit (triangle_intersect.h);
                    // NaN coordinates make the packed test agree.
                    const Vec3f normal = cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
                    usable = !(normal.x == 0.0f && normal.y == 0.0f && normal.z == 0.0f);
                }
                const Vec3f* vertices[3] = {&tri.v0, &tri.v1, &tri.v2};
                for (int vertex = 0; vertex < 3; ++vertex) {
                    for (int axis = 0; axis < 3; ++axis) {
                        pack.v[vertex][axis][lane] = usable ? (*vertices[vertex])[axis] : nan;
                    }
                }
            }
        }
    }

    // Relative costs of one wide-node box test and one 4-triangle pack test;
    // SAH-like ratios around 1 gave the fewest instructions (pack cost 0.7 to
    // 1.5 and 2 to 8 packs per leaf all within 0.3% on Sponza diffuse rays).
    static constexpr float kNodeCost = 1.0f;
    static constexpr float kPackCost = 1.0f;
    static constexpr uint32_t kMaxLeafPacks = 4;  // larger binary leaves stay whole (up to 16 packs)

    const Bvh& bvh_;
    const std::vector<Triangle>& triangles_;
    std::unique_ptr<NodeInfo[]> info_;
    std::atomic<bool> too_many_packs_{false};
    WideBvh<N>* out_ = nullptr;
};

}  // namespace

template <int N>
WideBvh<N> collapse_bvh(const Bvh& bvh, const std::vector<Triangle>& triangles) {
    return Collapser<N>(bvh, triangles).run();
}

template WideBvh<4> collapse_bvh<4>(const Bvh&, const std::vector<Triangle>&);
template WideBvh<8> collapse_bvh<8>(const Bvh&, const std::vector<Triangle>&);

}  // namespace rf
