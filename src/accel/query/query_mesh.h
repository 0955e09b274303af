// The form MeshQueries' traversals read (mesh_queries.cpp): the canonical
// BVH's nodes and a copy of the triangles in leaf-slot order, each with its
// triangle index and a zero-area flag, so a leaf's triangles are contiguous
// and no prim_indices indirection is needed.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::query {

inline constexpr uint32_t kZeroAreaBit = 0x80000000u;  // triangle indices stay below 2^31

// 40 bytes: a triangle referenced by one leaf slot.
struct SlotTriangle {
    Triangle tri;
    uint32_t tag = 0;  // triangle index | kZeroAreaBit when cross(v1 - v0, v2 - v0) is exactly zero
    RF_HDI uint32_t prim() const { return tag & ~kZeroAreaBit; }
    RF_HDI bool zero_area() const { return (tag & kZeroAreaBit) != 0; }
};

// node_count == 0 is the empty mesh.
struct QueryView {
    const BvhNode* nodes = nullptr;
    const SlotTriangle* slots = nullptr;  // indexed by the leaves' first .. first + count
    uint32_t node_count = 0;
};

// The stack every traversal here uses: the canonical BVH is at most
// kBvhMaxDepth inner nodes deep, and a depth-first walk keeps at most one
// entry per level (two where both children are pushed).
inline constexpr int kQueryStackSize = 2 * kBvhMaxDepth;

// slots[s] = triangles[bvh.prim_indices[s]] with its tag (parallel over slots).
void fill_slot_triangles(const Bvh& bvh, std::span<const Triangle> triangles, std::vector<SlotTriangle>& slots);

}  // namespace rf::query
