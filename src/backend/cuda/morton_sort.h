// The front of the Morton-ordered device builders (LBVH, lbvh_build.cu;
// HLBVH2, hlbvh2_build.cu; PLOC, ploc_build.cu), shared so all sort the
// same way: triangle boxes and the centroid bounds (a block-wise union, then
// one block over the block results), 30- or 63-bit Morton codes of the box
// centres with the CPU's MortonQuantizer, and one stable
// cub::DeviceRadixSort of (code, triangle), bit-identical to
// morton_tree.cpp's. Host-only declarations; the kernels live in
// morton_sort.cu.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// The sorted triangles: per-triangle boxes, the sorted codes and the
// stable order (sorted position -> triangle).
template <class Key>
struct DeviceMortonOrder {
    DeviceBuffer<Box3f> boxes;
    DeviceBuffer<Key> keys;
    DeviceBuffer<uint32_t> order;
    // The codes' frame (1 box). Kept with the order, to the end of the
    // build: the LBVH always counted it live to the end, and its peak report
    // stays as it was.
    DeviceBuffer<Box3f> bounds;
};

// Uploads `triangles` (n >= 1), computes their boxes, the centroid bounds and
// the codes (uint32_t: 30 bits, uint64_t: 63 bits), and sorts; sets
// stages.upload_ms, bounds_ms, morton_ms and sort_ms. Buffer names start
// with `label` (out-of-memory errors name them); all are counted by
// build.meter, and everything but the result is freed before it returns.
template <class Key>
DeviceMortonOrder<Key> sort_triangles_by_morton_codes(std::span<const Triangle> triangles, const std::string& label,
                                                      BuildContext& build);

}  // namespace rf::cuda
