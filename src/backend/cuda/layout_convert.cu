// Conversions of the canonical BVH to the GPU traversal layouts on the device
// (issue 7 item 5), giving exactly the CPU's arrays:
//
// Aila and Laine 2009 node pairs (aila_laine_steps.h; the CPU's
// convert_to_aila_laine walks depth first):
//  1. parents:  one thread per inner node links its children to it;
//  2. sizes:    one thread per leaf walks up; an arrival counter per inner
//               node lets only the second child go on, summing both
//               subtrees (node pairs, leaf-list float4s, leaves, references);
//  3. emit:     one thread per node sums its depth-first position over its
//               ancestors (O(depth), no global synchronisation) and writes
//               its node pair or its leaf list there.
//
// CWBVH, Ylitie, Karras and Laine 2017 (cwbvh_refine_steps.h,
// cwbvh_collapse_steps.h, cwbvh_encode_steps.h, cwbvh_emit_steps.h; the
// CPU's build_cwbvh), after the host's validation of the canonical BVH:
//  0. refine:   canonical leaves split to single-triangle subtrees, one
//               thread per canonical node, their places by a
//               cub::DeviceScan::ExclusiveSum of the added node counts;
//  1. parents:  one thread per refined inner node;
//  2. DP:       section 3's cost tables bottom up, one thread per refined
//               leaf, the second child to arrive solving the parent;
//  3. discover: level by level from the root, one thread per wide node: its
//               slots from the DP's decisions, the section 4.2 auction, its
//               own counts; cub::DeviceScan::ExclusiveSum of the inner counts
//               places the children, in slot order, in the next level;
//  4. totals:   level by level bottom up, subtree counts;
//  5. emit:     level by level top down: each wide node's depth-first
//               numbers from its parent (the CPU's numbering, see
//               cwbvh_emit_steps.h), the section 4.1 quantisation, meta
//               bytes and leaf triangles written in place.
// device_ms: the kernels (CUDA events, from the first kernel to the last,
// the 8-byte queue-size reads between CWBVH levels included); uploads,
// downloads and the host's validation of the canonical BVH are not in it.
#include <cuda_runtime.h>

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

#include "accel/bvh/builders/karras_tree_steps.h"
#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/aila_laine_steps.h"
#include "accel/bvh/layout/cwbvh_collapse_steps.h"
#include "accel/bvh/layout/cwbvh_emit_steps.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel/bvh/layout/cwbvh_refine_steps.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/morton_sort.h"
#include "backend/backends.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

constexpr int kBlockSize = 256;

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

// ---- Aila-Laine node pairs ------------------------------------------------

__global__ void aila_laine_parents_kernel(const BvhNode* nodes, uint32_t n, uint32_t* parent) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n && !nodes[i].is_leaf()) aila_laine::parent_links_of(nodes, i, parent);
}

__global__ void aila_laine_sizes_kernel(const BvhNode* nodes, uint32_t n, const uint32_t* parent,
                                        aila_laine::SubtreeSize* size, uint32_t* arrivals) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n && nodes[i].is_leaf())
        aila_laine::propagate_sizes_from_leaf<karras::AtomicArrival>(nodes, parent, i, size, arrivals);
}

__global__ void aila_laine_emit_kernel(const BvhNode* nodes, uint32_t n, const uint32_t* parent,
                                       const aila_laine::SubtreeSize* size, const uint32_t* prim_indices,
                                       const Triangle* triangles, AilaLaineNode* out_nodes,
                                       AilaLaineFloat4* out_triangles) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    const aila_laine::Position at = aila_laine::position_of(nodes, parent, size, i);
    if (nodes[i].is_leaf()) {
        aila_laine::write_leaf_list(nodes[i], prim_indices, triangles, out_triangles + at.float4_offset);
    } else {
        out_nodes[at.inner_index] = aila_laine::node_pair_at(nodes, size, i, at);
    }
}

// What the device passes assume and the CPU checks on its walk (messages
// prefixed by `who`, the CPU function's name): forward links in range, every
// node but the root with exactly one parent (so parent walks end at the
// root), leaf ranges and triangle indices in range; with `max_depth`, at most
// that many inner nodes on a path.
struct CanonicalTotals {
    size_t inner = 0, leaves = 0, references = 0;
    size_t aila_laine_float4s = 0;  // leaf lists of the node-pair layout
    size_t refined_extra = 0;       // CWBVH: nodes added by leaf refinement
};

CanonicalTotals validate_canonical(const Bvh& bvh, size_t triangle_count, const std::string& who, int max_depth) {
    const size_t n = bvh.nodes.size();
    std::vector<uint8_t> parents(n, 0);
    std::vector<int> depth(n, 0);
    depth[0] = 1;
    CanonicalTotals t;
    for (size_t i = 0; i < n; ++i) {
        const BvhNode& node = bvh.nodes[i];
        if (i != 0 && parents[i] != 1)
            throw Error(who + "_on_device: node " + std::to_string(i) + " is not reached exactly once");
        if (node.is_leaf()) {
            if (size_t{node.first} + node.count > bvh.prim_indices.size())
                throw Error(who + ": leaf primitive range out of bounds");
            for (uint32_t slot = node.first; slot < node.first + node.count; ++slot) {
                if (bvh.prim_indices[slot] >= triangle_count)
                    throw Error(who + ": primitive index " + std::to_string(bvh.prim_indices[slot]) +
                                " out of range");
            }
            t.aila_laine_float4s += size_t{node.count} * kAilaLaineTriangleStride + 1;
            t.refined_extra += cwbvh::refined_extra(node);
            ++t.leaves;
            t.references += node.count;
            continue;
        }
        if (max_depth > 0 && depth[i] > max_depth) throw Error(who + ": BVH deeper than kBvhMaxDepth");
        const uint32_t left = node.first;
        if (left <= i || size_t{left} + 1 >= n) throw Error(who + ": child link out of range");
        for (uint32_t c = left; c < left + 2; ++c) {
            parents[c] = uint8_t(std::min(parents[c] + 1, 2));
            depth[c] = depth[i] + 1;
        }
        ++t.inner;
    }
    return t;
}

// ---- CWBVH ------------------------------------------------------------------

__global__ void cwbvh_extra_kernel(const BvhNode* canonical, uint32_t n, uint32_t* extra) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n) extra[i] = cwbvh::refined_extra(canonical[i]);
}

__global__ void cwbvh_refine_kernel(const BvhNode* canonical, uint32_t n, const uint32_t* prim_indices,
                                    const Triangle* triangles, const uint32_t* extra_base,
                                    cwbvh::RefineRef* scratch, cwbvh::RefinedNode* refined) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n) cwbvh::refine_node(canonical, n, prim_indices, triangles, i, extra_base[i], scratch, refined);
}

__global__ void cwbvh_parents_kernel(const cwbvh::RefinedNode* nodes, uint32_t n, uint32_t* parent) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n && !nodes[i].leaf) cwbvh::parent_links_of(nodes, i, parent);
}

__global__ void cwbvh_dp_kernel(cwbvh::RefinedNode* nodes, uint32_t n, const uint32_t* parent, float* cost,
                                cwbvh::Choice* choices, uint32_t* arrivals) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n || !nodes[i].leaf) return;
    const float bias = cwbvh::area_bias(nodes[0].box);  // the refined root's box
    cwbvh::count_and_solve_from_leaf<karras::AtomicArrival>(nodes, parent, i, bias, cost, choices, arrivals);
}

__global__ void cwbvh_discover_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::discover(view, start + k);
}

__global__ void cwbvh_enqueue_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::enqueue_children(view, start + k, start + count);
}

__global__ void cwbvh_totals_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::total(view, start + k);
}

__global__ void cwbvh_emit_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::emit(view, start + k);
}

template <class T>
T download_one(const DeviceBuffer<T>& buffer, size_t index) {
    T value;
    RF_CUDA_CHECK(cudaMemcpy(&value, buffer.data() + index, sizeof(T), cudaMemcpyDeviceToHost));
    return value;
}

// The canonical BVH and its triangles uploaded, each buffer counted by `meter`.
struct CanonicalOnDevice {
    DeviceBuffer<BvhNode> nodes;
    DeviceBuffer<uint32_t> prims;
    DeviceBuffer<Triangle> triangles;
    CanonicalOnDevice(const Bvh& bvh, std::span<const Triangle> tris, MemoryMeter& meter, const std::string& what)
        : nodes(what + ": canonical nodes"), prims(what + ": primitive indices"), triangles(what + ": triangles") {
        meter.allocate(nodes, bvh.nodes.size());
        meter.allocate(prims, bvh.prim_indices.size());
        meter.allocate(triangles, tris.size());
        nodes.upload(bvh.nodes);
        prims.upload(bvh.prim_indices);
        triangles.upload(tris);
    }
};

}  // namespace

AilaLaineBvh convert_to_aila_laine_on_device(const Bvh& bvh, std::span<const Triangle> triangles,
                                             double* device_ms, int device) {
    if (device_ms) *device_ms = 0.0;
    AilaLaineBvh out;
    if (bvh.nodes.empty()) return out;
    const CanonicalTotals checked = validate_canonical(bvh, triangles.size(), "convert_to_aila_laine", kBvhMaxDepth);
    constexpr size_t kMaxLink = static_cast<size_t>(kAilaLaineEntrySentinel);
    if (checked.inner >= kMaxLink) throw Error("convert_to_aila_laine: too many nodes for 31-bit links");
    if (checked.aila_laine_float4s > kMaxLink)
        throw Error("convert_to_aila_laine: too many leaf triangles for 31-bit links");
    const aila_laine::SubtreeSize total{uint32_t(checked.inner), uint32_t(checked.aila_laine_float4s),
                                        uint32_t(checked.leaves), uint32_t(checked.references)};
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    const auto n = static_cast<uint32_t>(bvh.nodes.size());
    MemoryMeter meter;
    EventTimer timer;

    CanonicalOnDevice input(bvh, triangles, meter, "node pairs");
    DeviceBuffer<BvhNode>& nodes = input.nodes;
    DeviceBuffer<uint32_t>& prims = input.prims;
    DeviceBuffer<Triangle>& tris = input.triangles;

    DeviceBuffer<uint32_t> parent("node pairs: parents"), arrivals("node pairs: arrival counters");
    DeviceBuffer<aila_laine::SubtreeSize> size("node pairs: subtree sizes");
    DeviceBuffer<AilaLaineNode> out_nodes("node pairs: nodes");
    DeviceBuffer<AilaLaineFloat4> out_tris("node pairs: leaf lists");
    meter.allocate(parent, n);
    meter.allocate(arrivals, n);
    meter.allocate(size, n);
    meter.allocate(out_nodes, total.inner_nodes);
    meter.allocate(out_tris, total.float4s);

    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(parent.data(), 0xFF, parent.bytes()));  // root: kNoParent
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    aila_laine_parents_kernel<<<blocks_for(n), kBlockSize>>>(nodes.data(), n, parent.data());
    aila_laine_sizes_kernel<<<blocks_for(n), kBlockSize>>>(nodes.data(), n, parent.data(), size.data(),
                                                           arrivals.data());
    aila_laine_emit_kernel<<<blocks_for(n), kBlockSize>>>(nodes.data(), n, parent.data(), size.data(),
                                                          prims.data(), tris.data(), out_nodes.data(),
                                                          out_tris.data());
    const double ms = timer.stop_ms();
    if (device_ms) *device_ms = ms;

    out.nodes = download_all(out_nodes, total.inner_nodes);
    out.triangles = download_all(out_tris, total.float4s);
    out.bounds = bvh.nodes[0].bounds;
    out.root = bvh.nodes[0].is_leaf() ? ~int32_t{0} : 0;
    out.leaf_count = total.leaves;
    out.triangle_refs = total.triangle_refs;
    return out;
}

CwbvhBvh build_cwbvh_on_device(const Bvh& bvh, std::span<const Triangle> triangles, double* device_ms,
                               int device) {
    if (device_ms) *device_ms = 0.0;
    CwbvhBvh out;
    if (bvh.nodes.empty()) return out;
    if (bvh.prim_indices.size() >= std::numeric_limits<uint32_t>::max())
        throw Error("build_cwbvh: too many triangle references");
    const CanonicalTotals checked = validate_canonical(bvh, triangles.size(), "build_cwbvh", 0);
    if (bvh.nodes.size() + checked.refined_extra >= std::numeric_limits<uint32_t>::max())
        throw Error("build_cwbvh: too many nodes after leaf refinement");
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    const auto canonical_count = static_cast<uint32_t>(bvh.nodes.size());
    const auto n = static_cast<uint32_t>(canonical_count + checked.refined_extra);  // refined nodes
    const size_t references = checked.references;  // one refined leaf each
    MemoryMeter meter;
    EventTimer timer;

    CanonicalOnDevice input(bvh, triangles, meter, "CWBVH");
    DeviceBuffer<BvhNode>& canonical = input.nodes;
    DeviceBuffer<uint32_t>& prims = input.prims;
    DeviceBuffer<Triangle>& tris = input.triangles;

    // Refinement's state, then the DP's, then the emission's per-wide-node
    // arrays (at most one wide node per refined node).
    DeviceBuffer<uint32_t> extra("CWBVH: refinement sizes"), extra_base("CWBVH: refinement offsets");
    DeviceBuffer<cwbvh::RefineRef> scratch("CWBVH: leaf references");
    DeviceBuffer<cwbvh::RefinedNode> nodes("CWBVH: refined nodes");
    meter.allocate(extra, canonical_count);
    meter.allocate(extra_base, canonical_count);
    meter.allocate(scratch, std::max<size_t>(checked.refined_extra, 1));
    meter.allocate(nodes, n);
    DeviceBuffer<uint32_t> parent("CWBVH: parents"), arrivals("CWBVH: arrival counters");
    DeviceBuffer<float> cost("CWBVH: DP cost tables");
    DeviceBuffer<cwbvh::Choice> choices("CWBVH: DP decisions");
    meter.allocate(parent, n);
    meter.allocate(arrivals, n);
    meter.allocate(cost, size_t{n} * cwbvh::kWidth);
    meter.allocate(choices, n);
    DeviceBuffer<uint32_t> wide_refined("CWBVH: wide-node queue"), slots("CWBVH: slot children"),
        inner_count("CWBVH: inner-child counts"), first_child("CWBVH: first children"),
        wide_index("CWBVH: wide-node indices"), counters("CWBVH: leaf-slot and error counters");
    DeviceBuffer<cwbvh::OwnCounts> own("CWBVH: own counts"), subtree("CWBVH: subtree counts"),
        before("CWBVH: depth-first prefixes");
    DeviceBuffer<CwbvhNode> out_nodes("CWBVH: nodes");
    DeviceBuffer<CwbvhTriangle> out_tris("CWBVH: triangles");
    meter.allocate(wide_refined, n);
    meter.allocate(slots, size_t{n} * cwbvh::kWidth);
    meter.allocate(inner_count, n);
    meter.allocate(first_child, n);
    meter.allocate(wide_index, n);
    meter.allocate(counters, 2);
    meter.allocate(own, n);
    meter.allocate(subtree, n);
    meter.allocate(before, n);
    meter.allocate(out_nodes, n);
    meter.allocate(out_tris, references);
    size_t scan_bytes = 0, refine_scan_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, scan_bytes, inner_count.data(), first_child.data(), n));
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, refine_scan_bytes, extra.data(), extra_base.data(),
                                                canonical_count));
    scan_bytes = std::max(std::max(scan_bytes, refine_scan_bytes), size_t{1});
    DeviceBuffer<unsigned char> scan_storage("CWBVH: scan temporary storage");
    meter.allocate(scan_storage, scan_bytes);

    const cwbvh::EmitView view{nodes.data(),       choices.data(),       tris.data(),       wide_refined.data(),
                               slots.data(),       own.data(),           inner_count.data(), first_child.data(),
                               subtree.data(),     wide_index.data(),    before.data(),     out_nodes.data(),
                               out_tris.data(),    counters.data(),      counters.data() + 1};
    timer.start();
    // 0. Leaf refinement: sizes, their scan, one thread per canonical node.
    cwbvh_extra_kernel<<<blocks_for(canonical_count), kBlockSize>>>(canonical.data(), canonical_count,
                                                                    extra.data());
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_storage.data(), scan_bytes, extra.data(), extra_base.data(),
                                                canonical_count));
    cwbvh_refine_kernel<<<blocks_for(canonical_count), kBlockSize>>>(canonical.data(), canonical_count,
                                                                     prims.data(), tris.data(), extra_base.data(),
                                                                     scratch.data(), nodes.data());
    // 1-2. Parents, the DP.
    RF_CUDA_CHECK(cudaMemsetAsync(parent.data(), 0xFF, parent.bytes()));  // root: kNoParent
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(wide_refined.data(), 0, sizeof(uint32_t)));  // the root covers refined node 0
    RF_CUDA_CHECK(cudaMemsetAsync(wide_index.data(), 0, sizeof(uint32_t)));
    RF_CUDA_CHECK(cudaMemsetAsync(before.data(), 0, sizeof(cwbvh::OwnCounts)));
    cwbvh_parents_kernel<<<blocks_for(n), kBlockSize>>>(nodes.data(), n, parent.data());
    cwbvh_dp_kernel<<<blocks_for(n), kBlockSize>>>(nodes.data(), n, parent.data(), cost.data(), choices.data(),
                                                   arrivals.data());
    // 3-5. The wide tree level by level.
    struct Level {
        uint32_t start, count;
    };
    std::vector<Level> levels;
    for (Level level{0, 1}; level.count != 0;) {
        if (levels.size() == size_t{kCwbvhMaxDepth})
            throw Error("build_cwbvh: wide BVH deeper than " + std::to_string(kCwbvhMaxDepth) + " levels");
        levels.push_back(level);
        cwbvh_discover_kernel<<<blocks_for(level.count), kBlockSize>>>(view, level.start, level.count);
        RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_storage.data(), scan_bytes, inner_count.data() + level.start,
                                                    first_child.data() + level.start, level.count));
        const uint32_t last = level.start + level.count - 1;
        const uint32_t next_count = download_one(first_child, last) + download_one(inner_count, last);
        cwbvh_enqueue_kernel<<<blocks_for(level.count), kBlockSize>>>(view, level.start, level.count);
        level = {level.start + level.count, next_count};
    }
    for (size_t l = levels.size(); l-- > 0;)
        cwbvh_totals_kernel<<<blocks_for(levels[l].count), kBlockSize>>>(view, levels[l].start, levels[l].count);
    for (const Level& level : levels)
        cwbvh_emit_kernel<<<blocks_for(level.count), kBlockSize>>>(view, level.start, level.count);
    const double ms = timer.stop_ms();
    if (device_ms) *device_ms = ms;

    const cwbvh::OwnCounts total = download_one(subtree, 0);
    const std::vector<uint32_t> counts = download_all(counters, 2);
    if (counts[1] & cwbvh::kErrorQuantize)
        throw Error("build_cwbvh: a box cannot be quantised (coordinates too large)");
    if (total.triangles != references || total.inner + 1u > n)
        throw Error("build_cwbvh_on_device: inconsistent wide tree (device error)");
    out.nodes = download_all(out_nodes, total.inner + 1u);
    out.triangles = download_all(out_tris, references);
    out.leaf_count = counts[0];
    out.depth = static_cast<int>(levels.size());
    return out;
}

}  // namespace rf::cuda
