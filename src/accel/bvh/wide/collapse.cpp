// Binary-to-wide BVH collapse, greedy by surface area as in Wald, Benthin and
// Boulos 2008 and Embree's BVH-N builders: a wide node starts with the binary
// node's two children and repeatedly opens the largest-area inner child until
// its N slots are full. Opening the largest box first minimises the wide
// node's SAH cost greedily, since the expected number of child-box tests a
// ray does below a node is proportional to the children's areas.
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

    // Inner binary nodes with more references than one pack holds get opened
    // or become wide nodes; anything smaller becomes a leaf of packs.
    bool expandable(uint32_t b) const {
        return !bvh_.nodes[b].is_leaf() && refs_[b] > uint32_t(kTrianglePackWidth);
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
        if (expandable(b)) {
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
        int used = 2;
        slots[0] = bvh_.nodes[b].first;
        slots[1] = bvh_.nodes[b].first + 1;
        while (used < N) {
            int best = -1;
            float best_area = -1.0f;
            for (int i = 0; i < used; ++i) {
                if (!expandable(slots[i])) continue;
                const float area = bvh_.nodes[slots[i]].bounds.surface_area();
                if (area > best_area) {
                    best_area = area;
                    best = i;
                }
            }
            if (best < 0) break;
            const uint32_t opened = slots[best];
            slots[best] = bvh_.nodes[opened].first;
            slots[used++] = bvh_.nodes[opened].first + 1;
        }
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

    const Bvh& bvh_;
    const std::vector<Triangle>& triangles_;
    std::vector<uint32_t> refs_;
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
