// The compact GPU node-pair layout of Aila and Laine 2009, "Understanding the
// Efficiency of Ray Traversal on GPUs" (HPG 2009), converted from the
// canonical binary BVH (rayforge/accel/bvh/bvh.h).
//
// An inner node holds the boxes of both of its children and both child links
// in 64 bytes (four float4s), so one node fetch gives everything a ray needs
// to decide where to go next; the canonical root's own box is never tested.
// Leaves are lists of triangles terminated by a sentinel, stored contiguously
// in the order a depth-first traversal reaches them.
//
// Leaf triangles: the paper stores Woop's unit-triangle transform (three
// float4 rows). rayforge promises watertight hits bit-identical to the scalar
// test (trace/triangle_intersect.h), which the Woop form cannot give (its t,
// u, v differ and it leaks along shared edges), and re-testing its accepted
// candidates would need the vertices as well. So each triangle is stored as
// its original vertices instead, still three float4s (48 bytes, the same
// fetch size as Woop's): v0, v1, v2 in xyz and the triangle index bit-cast
// into v0.w. The traversal runs the watertight test on them directly.
//
// All arrays are plain vectors of 16-byte-aligned POD structs, so a CUDA
// backend can upload them as they are; AilaLaineView is the pointer view the
// shared host/device traversal (trace/aila_laine_traversal.h) reads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// CUDA's float4 without depending on CUDA headers (same size and alignment).
struct alignas(16) AilaLaineFloat4 {
    float x, y, z, w;
};
static_assert(sizeof(AilaLaineFloat4) == 16, "AilaLaineFloat4 must match float4");

// One node pair (64 bytes, one fetch): children c0 and c1.
//   xy0 = (c0.lo.x, c0.hi.x, c0.lo.y, c0.hi.y)
//   xy1 = (c1.lo.x, c1.hi.x, c1.lo.y, c1.hi.y)
//   z   = (c0.lo.z, c0.hi.z, c1.lo.z, c1.hi.z)
//   link[c] >= 0: index of the inner node c in AilaLaineBvh::nodes;
//   link[c] <  0: ~(index of the leaf's first float4 in AilaLaineBvh::triangles).
// The paper packs the links into a float4 by bit-casting; int lanes are the
// same bytes without the casts.
struct alignas(16) AilaLaineNode {
    AilaLaineFloat4 xy0;
    AilaLaineFloat4 xy1;
    AilaLaineFloat4 z;
    int32_t link[2];
    int32_t pad[2];  // keeps the node at four float4s
};
static_assert(sizeof(AilaLaineNode) == 64, "AilaLaineNode must stay 64 bytes");

// Stack-bottom marker and "no root" value: larger than any node index (the
// converter checks) and non-negative, so it is neither a node nor a leaf link.
inline constexpr int32_t kAilaLaineEntrySentinel = 0x76543210;
// A leaf list ends with a float4 whose w bits are this (no valid triangle
// index, see SceneGeometry) and whose x bits are 0x80000000 as in the paper.
// The traversal checks w only: a real vertex can have x == -0.0f.
inline constexpr uint32_t kAilaLaineLeafEndW = 0xFFFFFFFFu;
inline constexpr uint32_t kAilaLaineLeafEndX = 0x80000000u;
// float4s per stored triangle (v0, v1, v2).
inline constexpr int kAilaLaineTriangleStride = 3;

// What the traversal reads: raw pointers, valid on whichever side holds the
// arrays. root is 0 (node 0) when the canonical root is inner, a leaf link
// when the whole BVH is one leaf, and kAilaLaineEntrySentinel when empty.
struct AilaLaineView {
    const AilaLaineNode* nodes = nullptr;
    const AilaLaineFloat4* triangles = nullptr;
    int32_t root = kAilaLaineEntrySentinel;
    uint32_t node_count = 0;
};

struct AilaLaineBvh {
    std::vector<AilaLaineNode> nodes;          // one per canonical inner node, depth-first
    std::vector<AilaLaineFloat4> triangles;    // leaf lists, each sentinel-terminated
    int32_t root = kAilaLaineEntrySentinel;
    Box3f bounds;                              // the canonical root's box (not traversed)
    size_t leaf_count = 0;
    size_t triangle_refs = 0;                  // triangles stored over all leaves

    [[nodiscard]] AilaLaineView view() const {
        return {nodes.data(), triangles.data(), root, static_cast<uint32_t>(nodes.size())};
    }
    [[nodiscard]] size_t memory_bytes() const {
        return nodes.size() * sizeof(AilaLaineNode) + triangles.size() * sizeof(AilaLaineFloat4);
    }
};

// Converts `bvh` (built over `triangles`). Inner nodes keep the canonical
// depth-first order, so a node's first inner child usually follows it in
// memory; leaf lists are laid out in the same depth-first order. Throws
// rf::Error when the BVH is malformed (links or prim indices out of range,
// deeper than kBvhMaxDepth) or too large for 31-bit links.
// rf::cuda::convert_to_aila_laine_on_device gives the same arrays
// (aila_laine_steps.h).
AilaLaineBvh convert_to_aila_laine(const Bvh& bvh, std::span<const Triangle> triangles);

}  // namespace rf
