// Binary-to-wide BVH collapse by the cost-optimal dynamic programme of Ylitie,
// Karras and Laine 2017 ("Efficient incoherent ray traversal on GPUs through
// compressed wide BVHs", section 3), adapted to this CPU layout: every binary
// subtree is assigned, bottom-up, the cheapest way to cover it with up to N
// slots of its parent wide node, each slot a wide node or a leaf of 4-triangle
// packs, under an SAH cost (node tests and pack tests weighted by box area).
// Compared with greedy largest-area opening (Wald, Benthin and Boulos 2008)
// it fills nodes better and picks leaf sizes by cost: 8-12% fewer
// instructions per ray on Sponza.
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "accel/bvh/wide/wide_bvh.h"
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
        count_references();
        optimise();
        const Box3f& root = bvh_.nodes[0].bounds;
        for (int axis = 0; axis < 3; ++axis) {
            out.coord_scale = std::fmax(out.coord_scale, std::fmax(std::fabs(root.lo[axis]), std::fabs(root.hi[axis])));
        }
        out_ = &out;
        out.nodes.reserve(bvh_.nodes.size() / 2 + 1);
        out.packs.reserve(bvh_.prim_indices.size() / 2 + 1);
        out.nodes.emplace_back();
        if (expandable(0)) {
            build_node(0, 0);
        } else {
            // A tiny scene: the root is itself a leaf; give it a one-slot wide root.
            clear_node(0);
            set_slot(0, 0, 0);
        }
        return out;
    }

private:
    // Subtree triangle reference counts, bottom-up without assuming node order.
    void count_references() {
        refs_.assign(bvh_.nodes.size(), 0);
        std::vector<std::pair<uint32_t, bool>> stack{{0u, false}};
        while (!stack.empty()) {
            const auto [index, done] = stack.back();
            stack.pop_back();
            const BvhNode& node = bvh_.nodes[index];
            if (node.is_leaf()) {
                refs_[index] = node.count;
            } else if (!done) {
                stack.push_back({index, true});
                stack.push_back({node.first, false});
                stack.push_back({node.first + 1, false});
            } else {
                refs_[index] = refs_[node.first] + refs_[node.first + 1];
            }
        }
    }

    // Only a root with more references than one pack holds becomes a wide
    // node; a smaller scene gets a one-slot root holding a leaf.
    bool expandable(uint32_t b) const {
        return !bvh_.nodes[b].is_leaf() && refs_[b] > uint32_t(kTrianglePackWidth);
    }

    // Cost-optimal assignment (Ylitie, Karras and Laine 2017, section 3):
    // cost_[n * N + i - 1] is the least SAH cost of covering binary subtree n
    // with at most i wide-node slots, each slot a leaf of packs or a wide
    // node. A wide node costs kNodeCost times its box area (one SIMD test of
    // all N child boxes, whatever their number), a leaf kPackCost per pack
    // times its area. Evaluated children first; the choices are kept so the
    // wide tree can be read back top-down.
    void optimise() {
        const size_t count = bvh_.nodes.size();
        cost_.assign(count * N, 0.0f);
        split_.assign(count * N, 0);
        inner_.assign(count, 0);
        node_split_.assign(count, 1);
        constexpr float kInf = std::numeric_limits<float>::infinity();
        std::vector<std::pair<uint32_t, bool>> stack{{0u, false}};
        while (!stack.empty()) {
            const auto [n, done] = stack.back();
            stack.pop_back();
            const BvhNode& node = bvh_.nodes[n];
            if (!node.is_leaf() && !done) {
                stack.push_back({n, true});
                stack.push_back({node.first, false});
                stack.push_back({node.first + 1, false});
                continue;
            }
            const float area = node.bounds.surface_area();
            const uint32_t packs = (refs_[n] + kTrianglePackWidth - 1) / kTrianglePackWidth;
            float* cost = &cost_[size_t(n) * N];
            uint8_t* split = &split_[size_t(n) * N];
            if (node.is_leaf()) {
                for (int i = 0; i < N; ++i) cost[i] = area * kPackCost * float(packs);
                continue;
            }
            const float* left = &cost_[size_t(node.first) * N];
            const float* right = &cost_[size_t(node.first + 1) * N];
            // dist[j - 1]: both children with at most j slots between them.
            float dist[N];
            uint8_t dist_split[N];
            dist[0] = kInf;
            dist_split[0] = 0;
            for (int j = 2; j <= N; ++j) {
                float best = kInf;
                int best_k = 1;
                for (int k = 1; k < j; ++k) {
                    const float c = left[k - 1] + right[j - k - 1];
                    if (c < best) {
                        best = c;
                        best_k = k;
                    }
                }
                dist[j - 1] = best;
                dist_split[j - 1] = uint8_t(best_k | ((j - best_k) << 4));
            }
            const float as_node = area * kNodeCost + dist[N - 1];
            node_split_[n] = uint8_t(dist_split[N - 1] & 15);
            const float as_leaf = packs <= kMaxLeafPacks ? area * kPackCost * float(packs) : kInf;
            inner_[n] = as_node < as_leaf ? 1 : 0;
            cost[0] = inner_[n] ? as_node : as_leaf;
            split[0] = 0;
            for (int i = 2; i <= N; ++i) {
                if (dist[i - 1] < cost[i - 2]) {
                    cost[i - 1] = dist[i - 1];
                    split[i - 1] = dist_split[i - 1];
                } else {
                    cost[i - 1] = cost[i - 2];
                    split[i - 1] = split[i - 2];
                }
            }
        }
    }

    // Appends the slots that cover binary subtree n with at most i slots.
    void gather_slots(uint32_t n, int i, uint32_t* slots, int& used) const {
        const uint8_t s = split_[size_t(n) * N + size_t(i - 1)];
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

    // Fills slot `c` of wide node `w` with binary node `b` (recursing into it).
    void set_slot(uint32_t w, int c, uint32_t b) {
        const Box3f& box = bvh_.nodes[b].bounds;
        {
            WideNode<N>& node = out_->nodes[w];
            node.bounds[0][c] = box.lo.x;
            node.bounds[1][c] = box.hi.x;
            node.bounds[2][c] = box.lo.y;
            node.bounds[3][c] = box.hi.y;
            node.bounds[4][c] = box.lo.z;
            node.bounds[5][c] = box.hi.z;
        }
        if (inner_[b]) {
            const auto index = static_cast<uint32_t>(out_->nodes.size());
            out_->nodes.emplace_back();  // invalidates references into nodes
            out_->nodes[w].child[c] = index;
            build_node(b, index);
        } else {
            out_->nodes[w].child[c] = make_leaf(b);
        }
    }

    void build_node(uint32_t b, uint32_t w) {
        uint32_t slots[N];
        int used = 0;
        const uint32_t left = bvh_.nodes[b].first;
        const int k = node_split_[b];
        gather_slots(left, k, slots, used);
        gather_slots(left + 1, N - k, slots, used);
        clear_node(w);
        for (int i = 0; i < used; ++i) set_slot(w, i, slots[i]);
    }

    // Gathers the subtree's references into packs of four.
    uint32_t make_leaf(uint32_t b) {
        std::vector<uint32_t>& prims = scratch_;
        prims.clear();
        std::vector<uint32_t> stack{b};
        while (!stack.empty()) {
            const uint32_t index = stack.back();
            stack.pop_back();
            const BvhNode& node = bvh_.nodes[index];
            if (node.is_leaf()) {
                for (uint32_t s = node.first; s < node.first + node.count; ++s) prims.push_back(bvh_.prim_indices[s]);
            } else {
                stack.push_back(node.first + 1);
                stack.push_back(node.first);
            }
        }
        const auto pack_count = static_cast<uint32_t>((prims.size() + kTrianglePackWidth - 1) / kTrianglePackWidth);
        if (pack_count == 0 || pack_count > kWideMaxPacksPerLeaf) {
            throw Error("wide BVH collapse: a leaf holds " + std::to_string(prims.size()) +
                        " triangles (1 to " + std::to_string(kWideMaxPacksPerLeaf * kTrianglePackWidth) +
                        " supported)");
        }
        const auto first = static_cast<uint32_t>(out_->packs.size());
        if (first >= (1u << 27)) throw Error("wide BVH collapse: too many triangle packs");
        const float nan = std::numeric_limits<float>::quiet_NaN();
        for (uint32_t p = 0; p < pack_count; ++p) {
            TrianglePack pack;
            for (int lane = 0; lane < kTrianglePackWidth; ++lane) {
                const size_t slot = size_t(p) * kTrianglePackWidth + size_t(lane);
                pack.prim[lane] = slot < prims.size() ? prims[slot] : kInvalidId;
                bool usable = slot < prims.size();
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
            out_->packs.push_back(pack);
        }
        ++out_->leaf_count;
        return wide_make_leaf(first, pack_count);
    }

    // Relative costs of one wide-node box test and one 4-triangle pack test;
    // SAH-like ratios around 1 gave the fewest instructions (pack cost 0.7 to
    // 1.5 and 2 to 8 packs per leaf all within 0.3% on Sponza diffuse rays).
    static constexpr float kNodeCost = 1.0f;
    static constexpr float kPackCost = 1.0f;
    static constexpr uint32_t kMaxLeafPacks = 4;  // larger binary leaves stay whole (up to 16 packs)

    const Bvh& bvh_;
    const std::vector<Triangle>& triangles_;
    std::vector<uint32_t> refs_;
    std::vector<float> cost_;
    std::vector<uint8_t> split_;       // per (node, slots): left | right << 4, 0 = one slot
    std::vector<uint8_t> inner_;       // one slot: wide node (1) or leaf (0)
    std::vector<uint8_t> node_split_;  // as a wide node: slots given to the left child
    std::vector<uint32_t> scratch_;
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
