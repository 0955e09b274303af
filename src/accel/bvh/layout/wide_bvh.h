// Wide (4- and 8-ary) BVH layouts collapsed from the canonical binary BVH,
// after the multi-BVH of Wald, Benthin and Boulos 2008 ("Getting rid of
// packets") and Ernst and Greiner 2008 ("Multi bounding volume hierarchies"):
// each node stores the boxes of its N children as structure-of-arrays
// (lo.x[N], hi.x[N], lo.y[N], ...), so one SIMD slab test checks all of them.
// Leaf triangles are stored four at a time, vertex coordinates as
// structure-of-arrays, so one SSE watertight test handles a whole pack.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// A child reference: an inner node index, a leaf (flag | first pack << 4 |
// pack count - 1), or the empty slot.
inline constexpr uint32_t kWideLeafFlag = 0x80000000u;
inline constexpr uint32_t kWideEmptyRef = 0x7FFFFFFFu;
inline constexpr uint32_t kWideMaxPacksPerLeaf = 16;
inline constexpr int kTrianglePackWidth = 4;

inline bool wide_is_leaf(uint32_t ref) { return (ref & kWideLeafFlag) != 0; }
inline uint32_t wide_leaf_first_pack(uint32_t ref) { return (ref & ~kWideLeafFlag) >> 4; }
inline uint32_t wide_leaf_pack_count(uint32_t ref) { return (ref & 15u) + 1u; }
inline uint32_t wide_make_leaf(uint32_t first_pack, uint32_t pack_count) {
    return kWideLeafFlag | (first_pack << 4) | (pack_count - 1u);
}

// One N-wide node. bounds[2 * axis + side][child], side 0 = lo, 1 = hi; empty
// slots have lo = +inf, hi = -inf, which no ray can enter.
template <int N>
struct alignas(64) WideNode {
    float bounds[6][N];
    uint32_t child[N];
};
static_assert(sizeof(WideNode<4>) == 128, "WideNode<4> must stay two cache lines");
static_assert(sizeof(WideNode<8>) == 256, "WideNode<8> must stay four cache lines");

// Four triangles, vertices as v[vertex][axis][lane]. Empty slots and
// zero-area triangles (which never hit) get NaN coordinates: every test on
// them fails the t range check.
struct alignas(16) TrianglePack {
    float v[3][3][kTrianglePackWidth];
    uint32_t prim[kTrianglePackWidth];  // triangle index; kInvalidId for an empty slot
};
static_assert(sizeof(TrianglePack) == 160, "TrianglePack layout");

template <int N>
struct WideBvh {
    std::vector<WideNode<N>> nodes;  // nodes[0] is the root; empty for an empty scene
    std::vector<TrianglePack> packs;
    size_t leaf_count = 0;
    float coord_scale = 1.0f;  // largest |coordinate| of the scene's boxes (sizes the slab test's zero guard)

    [[nodiscard]] size_t memory_bytes() const {
        return nodes.size() * sizeof(WideNode<N>) + packs.size() * sizeof(TrianglePack);
    }
};

// Collapses `bvh` (built over `triangles`) into N-wide nodes (N = 4 or 8)
// with the SAH-optimal assignment of binary subtrees to wide nodes and leaves
// of Ylitie, Karras and Laine 2017 (section 3): leaves of up to four packs
// where that is cheaper, wide nodes filled as the cost model prefers. Binary
// leaves are never split, so leaves may hold up to 16 packs.
template <int N>
WideBvh<N> collapse_bvh(const Bvh& bvh, const std::vector<Triangle>& triangles);

// What a wide BVH adds to an accel's stats (accel/view_accel.h).
template <int N>
void describe_structure(const WideBvh<N>& bvh, AccelStats& s) {
    s.node_count = bvh.nodes.size();
    s.leaf_count = bvh.leaf_count;
    s.bytes = bvh.memory_bytes();
}

extern template WideBvh<4> collapse_bvh<4>(const Bvh&, const std::vector<Triangle>&);
extern template WideBvh<8> collapse_bvh<8>(const Bvh&, const std::vector<Triangle>&);

}  // namespace rf
