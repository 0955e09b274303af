// LBVH on the device (Karras 2012, "Maximizing Parallelism in the
// Construction of BVHs, Octrees, and k-d Trees"), building rf::build_lbvh's
// tree:
//  1. bounds:  one thread per triangle writes its box (the CPU's min/max
//     order) and the block-wise union of the box centres; one block unions
//     the block results into the centroid bounds.
//  2. morton:  30- or 63-bit codes of the box centres with the CPU's
//     MortonQuantizer (morton_code.h), built per thread from the bounds, so
//     the codes are bit-identical to morton_tree.cpp's.
//  3. sort:    cub::DeviceRadixSort::SortPairs of (code, triangle); stable,
//     so equal codes keep triangle order, as the CPU's radix sort does.
//  4. inner:   one thread per inner node, karras::build_inner, parent links.
//  5. boxes:   one thread per leaf walks up; an atomic counter per inner node
//     lets only the second arrival go on (karras::propagate_boxes_from_leaf).
//  6. emission: the SAH leaf collapse and the canonical layout on the device
//     (raw_tree_emit.cu, with the parent links of step 4; it recomputes the
//     boxes, so a build for a BVH skips step 5), and the BVH back to the
//     host. A tree deeper than kBvhMaxDepth goes back raw instead, and the
//     host emits it (emit_karras_tree, the CPU LBVH's own refit and emitter,
//     whose depth-limited rebuild the device does not do). Either way the
//     BVH is build_lbvh's.
// Stages are timed with CUDA events around their kernels only; each stage's
// buffers live in its scope, so the peak holds only what one stage needs.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/builders/lbvh_emit.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/lbvh_build.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

// Stage 4: one thread per inner node.
template <class Key>
__global__ void inner_nodes_kernel(const Key* keys, uint32_t n, uint32_t* children, uint32_t* inner_parent,
                                   uint32_t* leaf_parent) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i + 1 >= n) return;
    karras::build_inner(keys, n, i, children + 2 * size_t{i}, inner_parent, leaf_parent);
}

// Stage 5: one thread per leaf.
__global__ void boxes_kernel(karras::BoxPassView tree, uint32_t n) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    karras::propagate_boxes_from_leaf<karras::AtomicArrival>(tree, i);
}

// The radix tree's links (karras_tree_steps.h's indexing).
struct KarrasLinks {
    DeviceBuffer<uint32_t> children;      // 2 (n - 1)
    DeviceBuffer<uint32_t> inner_parent;  // n - 1
    DeviceBuffer<uint32_t> leaf_parent;   // n
};

// Stage 4: inner nodes and parent links; the sorted codes are spent.
template <class Key>
KarrasLinks build_inner_nodes(DeviceBuffer<Key> sorted_keys, uint32_t n, BuildContext& build) {
    KarrasLinks links{DeviceBuffer<uint32_t>(build.meter, "LBVH: child references", 2 * size_t{n - 1}),
                      DeviceBuffer<uint32_t>(build.meter, "LBVH: inner node parents", n - 1),
                      DeviceBuffer<uint32_t>(build.meter, "LBVH: leaf parents", n)};
    build.timer.start();
    launch(inner_nodes_kernel<Key>, n - 1, sorted_keys.data(), n, links.children.data(), links.inner_parent.data(),
           links.leaf_parent.data());
    build.stages.inner_nodes_ms = build.timer.stop_ms();
    return links;
}

// Stage 5 for the raw tree: bottom-up boxes, then every array to the host.
template <class Key>
void refit_and_download(const DeviceMortonOrder<Key>& sorted, const KarrasLinks& links, uint32_t n,
                        BuildContext& build, DeviceKarrasTree& out) {
    DeviceBuffer<Box3f> inner_boxes(build.meter, "LBVH: inner node boxes", n - 1);
    DeviceBuffer<uint32_t> arrivals(build.meter, "LBVH: arrival counters", n - 1);
    const karras::BoxPassView view{links.children.data(), links.inner_parent.data(), links.leaf_parent.data(),
                                   sorted.boxes.data(),   sorted.order.data(),       inner_boxes.data(),
                                   arrivals.data()};
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    launch(boxes_kernel, n, view, n);
    build.stages.boxes_ms = build.timer.stop_ms();
    build.stages.peak_device_bytes = build.meter.peak();

    build.timer.start();
    out.order = download_all(sorted.order, n);
    out.children = download_all(links.children, 2 * size_t{n - 1});
    out.inner_parent = download_all(links.inner_parent, n - 1);
    out.leaf_parent = download_all(links.leaf_parent, n);
    out.arrivals = download_all(arrivals, n - 1);
    out.inner_boxes = download_all(inner_boxes, n - 1);
    out.triangle_boxes = download_all(sorted.boxes, n);
    build.stages.download_ms = build.timer.stop_ms();
}

// Stage 6: the emission on the device, which computes every box itself.
// False when the tree was too deep: then the order and the children came
// back in `out` for the host.
template <class Key>
bool emit_on_device(const DeviceMortonOrder<Key>& sorted, const KarrasLinks& links, uint32_t n,
                    const BvhBuildConfig& config, BuildContext& build, DeviceKarrasTree& out, Bvh& bvh) {
    DeviceRawTree tree;
    tree.children = links.children.data();
    tree.node_slots = n - 1;
    tree.root = 0;
    tree.primitives = n;
    tree.boxes = sorted.boxes.data();
    tree.boxes_by_triangle = true;
    tree.order = sorted.order.data();
    tree.node_parent = links.inner_parent.data();
    tree.leaf_parent = links.leaf_parent.data();
    const bool emitted = emit_raw_tree_on_device(tree, config, "LBVH", build, bvh);
    if (!emitted) {
        build.timer.start();
        out.order = download_all(sorted.order, n);
        out.children = download_all(links.children, 2 * size_t{n - 1});
        build.stages.download_ms += build.timer.stop_ms();
    }
    build.stages.peak_device_bytes = std::max(build.stages.peak_device_bytes, build.meter.peak());
    return emitted;
}

// The device pipeline for n >= 2 triangles. `raw`: every array of the tree
// comes back in `out`. Otherwise, with `config`, the device emits the BVH
// into `bvh` and returns true; false when the tree was too deep, and then
// only the order and the children came back in `out`.
template <class Key>
bool build_on_device(std::span<const Triangle> triangles, DeviceBuildStages& stages, DeviceKarrasTree& out, bool raw,
                     const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr, DeviceBvh* resident = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    BuildContext build(stages);
    build.resident = resident;
    // 1-3. Boxes, centroid bounds, Morton codes, the sort (morton_sort.cu).
    DeviceMortonOrder<Key> sorted = sort_triangles_by_morton_codes<Key>(triangles, "LBVH", build);
    // 4. Inner nodes and parent links.
    const KarrasLinks links = build_inner_nodes(std::move(sorted.keys), n, build);
    if (raw) {
        refit_and_download(sorted, links, n, build, out);
        return false;
    }
    return emit_on_device(sorted, links, n, *config, build, out, *bvh);
}

void check_input(std::span<const Triangle> triangles, int morton_bits) {
    if (morton_bits != 30 && morton_bits != 63) {
        throw Error("LBVH: Morton code bits must be 30 or 63, got " + std::to_string(morton_bits));
    }
    if (triangles.size() >= karras::kLeafRef) throw Error("Morton BVH build: more than 2^31-1 triangles");
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, int morton_bits, DeviceBuildStages& stages, int device,
               DeviceKarrasTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
               DeviceBvh* resident = nullptr) {
    check_input(triangles, morton_bits);
    const size_t n = triangles.size();
    if (n < 2) {  // no inner nodes: nothing for the device to do
        out.order.assign(n, 0u);
        return false;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    if (morton_bits == 30) return build_on_device<uint32_t>(triangles, stages, out, raw, config, bvh, resident);
    return build_on_device<uint64_t>(triangles, stages, out, raw, config, bvh, resident);
}

}  // namespace

DeviceKarrasTree build_karras_tree_on_device(std::span<const Triangle> triangles, int morton_bits,
                                             DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceKarrasTree tree;
    build_raw(triangles, morton_bits, stages ? *stages : local, device, tree, true);
    return tree;
}

Bvh build_lbvh_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config, int morton_bits,
                         DeviceBuildStages* stages, int device, DeviceBvh* resident) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    DeviceKarrasTree tree;
    Bvh bvh;
    if (build_raw(triangles, morton_bits, s, device, tree, false, &config, &bvh, resident)) {
        s.emitted_on_device = true;
        return bvh;
    }
    const auto start = std::chrono::steady_clock::now();
    bvh = emit_karras_tree(triangles, config, std::move(tree.order), tree.children);
    s.emit_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return bvh;
}

}  // namespace rf::cuda
