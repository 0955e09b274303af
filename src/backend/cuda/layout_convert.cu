// Conversions of the canonical BVH to the GPU traversal layouts on the device,
// giving exactly the CPU's arrays:
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
//               in level order places the children, in slot order, in the
//               next level (cwbvh_level_steps.h): each level's start and
//               size stay in a record on the device, grids and scans are
//               sized by bounds the host knows, and the host stops on a
//               lagging asynchronous copy (lagged_rounds.h), no blocking
//               read per level;
//  4. totals:   level by level bottom up, subtree counts;
//  5. emit:     level by level top down: each wide node's depth-first
//               numbers from its parent (the CPU's numbering, see
//               cwbvh_emit_steps.h), the section 4.1 quantisation, meta
//               bytes and leaf triangles written in place.
// device_ms: the kernels (CUDA events, from the first kernel to the last,
// the lagging level-record copies and the final one included); uploads,
// downloads and the host's validation of the canonical BVH are not in it.
//
// Two entries per layout: from a host Bvh (validated on the host, uploaded,
// the result downloaded; device_builders.h), and from a canonical BVH
// already on the device (layout_convert.h: a device builder's, written into
// the tracer's buffers, no host validation and only counts crossing).
#include <cuda_runtime.h>

#include <cub/device/device_reduce.cuh>
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
#include "accel/bvh/layout/cwbvh_level_steps.h"
#include "accel/bvh/layout/cwbvh_refine_steps.h"
#include "backend/backends.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/lagged_rounds.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/layout_convert.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

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

// Pass 1 of level `level`, its start and size read from its record; grids
// sized by the level's bound (cwbvh_level_steps.h).
__global__ void cwbvh_discover_kernel(cwbvh::EmitView view, const cwbvh::LevelRecord* records, uint32_t level,
                                      uint32_t width) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < width) cwbvh::discover_in_level(view, records, level, k);
}

__global__ void cwbvh_next_level_kernel(const uint32_t* prefix, const uint32_t* inner_count,
                                        cwbvh::LevelRecord* records, uint32_t level, uint32_t cap, uint32_t* error) {
    cwbvh::next_level_record(prefix, inner_count, records, level, cap, error);
}

__global__ void cwbvh_enqueue_kernel(cwbvh::EmitView view, const cwbvh::LevelRecord* records, uint32_t level,
                                     const uint32_t* prefix, uint32_t width) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < width) cwbvh::enqueue_in_level(view, records, level, prefix, k);
}

__global__ void cwbvh_first_level_kernel(cwbvh::LevelRecord* records) { records[0] = {0u, 1u}; }

__global__ void cwbvh_totals_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::total(view, start + k);
}

__global__ void cwbvh_emit_kernel(cwbvh::EmitView view, uint32_t start, uint32_t count) {
    const uint32_t k = blockIdx.x * kBlockSize + threadIdx.x;
    if (k < count) cwbvh::emit(view, start + k);
}

// The canonical BVH and its triangles uploaded, each buffer counted by `meter`.
struct CanonicalOnDevice {
    DeviceBuffer<BvhNode> nodes;
    DeviceBuffer<uint32_t> prims;
    DeviceBuffer<Triangle> triangles;
    CanonicalOnDevice(const Bvh& bvh, std::span<const Triangle> tris, MemoryMeter& meter, const std::string& what)
        : nodes(meter, what + ": canonical nodes", bvh.nodes.size()),
          prims(meter, what + ": primitive indices", bvh.prim_indices.size()),
          triangles(meter, what + ": triangles", tris.size()) {
        nodes.upload(bvh.nodes);
        prims.upload(bvh.prim_indices);
        triangles.upload(tris);
    }
    [[nodiscard]] DeviceCanonicalView view() const {
        return {nodes.data(), static_cast<uint32_t>(nodes.size()), prims.data(), prims.size(), triangles.data(),
                triangles.size()};
    }
};

// The CWBVH build's device arrays, all live to its end: refinement's state,
// then the DP's, then the emission's per-wide-node arrays (at most one wide
// node per refined node), then the scans' scratch.
struct CwbvhArrays {
    DeviceBuffer<uint32_t> extra, extra_base;
    DeviceBuffer<cwbvh::RefineRef> leaf_refs;
    DeviceBuffer<cwbvh::RefinedNode> nodes;
    DeviceBuffer<uint32_t> parent, arrivals;
    DeviceBuffer<float> cost;
    DeviceBuffer<cwbvh::Choice> choices;
    DeviceBuffer<uint32_t> wide_refined, slots, inner_count, first_child, level_prefix, wide_index, counters;
    DeviceBuffer<cwbvh::LevelRecord> level_records;
    DeviceBuffer<cwbvh::OwnCounts> own, subtree, before;
    DeviceBuffer<CwbvhNode> out_nodes;
    DeviceBuffer<CwbvhTriangle> out_tris;
    DeviceBuffer<uint8_t> scan_scratch;

    // canonical: canonical nodes; n: refined nodes; references: refined leaves.
    CwbvhArrays(MemoryMeter& m, uint32_t canonical, uint32_t n, size_t refined_extra, size_t references)
        : extra(m, "CWBVH: refinement sizes", canonical),
          extra_base(m, "CWBVH: refinement offsets", canonical),
          leaf_refs(m, "CWBVH: leaf references", std::max<size_t>(refined_extra, 1)),
          nodes(m, "CWBVH: refined nodes", n),
          parent(m, "CWBVH: parents", n),
          arrivals(m, "CWBVH: arrival counters", n),
          cost(m, "CWBVH: DP cost tables", size_t{n} * cwbvh::kWidth),
          choices(m, "CWBVH: DP decisions", n),
          wide_refined(m, "CWBVH: wide-node queue", n),
          slots(m, "CWBVH: slot children", size_t{n} * cwbvh::kWidth),
          inner_count(m, "CWBVH: inner-child counts", n),
          first_child(m, "CWBVH: first children", n),
          level_prefix(m, "CWBVH: level-order prefix of the inner counts", n),
          wide_index(m, "CWBVH: wide-node indices", n),
          counters(m, "CWBVH: leaf-slot and error counters", 2),
          level_records(m, "CWBVH: level records", size_t{kCwbvhMaxDepth} + 1),
          own(m, "CWBVH: own counts", n),
          subtree(m, "CWBVH: subtree counts", n),
          before(m, "CWBVH: depth-first prefixes", n),
          out_nodes(m, "CWBVH: nodes", n),
          out_tris(m, "CWBVH: triangles", references),
          scan_scratch(m, "CWBVH: scan temporary storage") {
        // Room for the largest scan, allocated outside the timed kernels.
        cub_reserve(scan_scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceScan::ExclusiveSum(temp, bytes, inner_count.data(), level_prefix.data(), n);
        });
        cub_reserve(scan_scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceScan::ExclusiveSum(temp, bytes, extra.data(), extra_base.data(), canonical);
        });
    }
    [[nodiscard]] cwbvh::EmitView view(const Triangle* triangles) const {
        return {nodes.data(),   choices.data(),    triangles,          wide_refined.data(), slots.data(),
                own.data(),     inner_count.data(), first_child.data(), subtree.data(),      wide_index.data(),
                before.data(),  out_nodes.data(),  out_tris.data(),    counters.data(),     counters.data() + 1};
    }
};

// A level of the wide tree: its wide nodes are [start, start + count).
struct WideLevel {
    uint32_t start, count;
};

// CWBVH 0: leaf refinement: sizes, their scan, one thread per canonical node.
void refine_leaves(const DeviceCanonicalView& input, CwbvhArrays& a) {
    const uint32_t canonical_count = input.node_count;
    launch(cwbvh_extra_kernel, canonical_count, input.nodes, canonical_count, a.extra.data());
    cub_run(a.scan_scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::ExclusiveSum(temp, bytes, a.extra.data(), a.extra_base.data(), canonical_count);
    });
    launch(cwbvh_refine_kernel, canonical_count, input.nodes, canonical_count, input.prim_indices, input.triangles,
           a.extra_base.data(), a.leaf_refs.data(), a.nodes.data());
}

// The nodes leaf refinement adds, for a tree the host has not walked: the
// same sizes summed on the device, one value back (the arrays are sized by it).
size_t refined_extra_on_device(const DeviceCanonicalView& input, MemoryMeter& meter) {
    DeviceBuffer<uint32_t> extra(meter, "CWBVH: refinement sizes to count", input.node_count);
    DeviceBuffer<uint32_t> sum(meter, "CWBVH: refined node total", 1);
    DeviceBuffer<uint8_t> scratch(meter, "CWBVH: reduction temporary storage");
    launch(cwbvh_extra_kernel, input.node_count, input.nodes, input.node_count, extra.data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceReduce::Sum(temp, bytes, extra.data(), sum.data(), input.node_count);
    });
    return download_value(sum.data());
}

// CWBVH 1-2: parents and the DP, after zeroing the counters and the root's
// emission entries.
void solve_collapse(CwbvhArrays& a, uint32_t n) {
    RF_CUDA_CHECK(cudaMemsetAsync(a.parent.data(), 0xFF, a.parent.bytes()));  // root: kNoParent
    RF_CUDA_CHECK(cudaMemsetAsync(a.arrivals.data(), 0, a.arrivals.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(a.counters.data(), 0, a.counters.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(a.wide_refined.data(), 0, sizeof(uint32_t)));  // the root covers refined node 0
    RF_CUDA_CHECK(cudaMemsetAsync(a.wide_index.data(), 0, sizeof(uint32_t)));
    RF_CUDA_CHECK(cudaMemsetAsync(a.before.data(), 0, sizeof(cwbvh::OwnCounts)));
    launch(cwbvh_parents_kernel, n, a.nodes.data(), n, a.parent.data());
    launch(cwbvh_dp_kernel, n, a.nodes.data(), n, a.parent.data(), a.cost.data(), a.choices.data(),
           a.arrivals.data());
}

// Level-record steps launched per round of the lagged loop: the levels
// past the last one are launched before the host knows (their kernels find
// a size of 0 and their scans redo the last prefix).
constexpr uint32_t kLevelsPerRound = 2;

// CWBVH 3: the wide tree level by level from the root (cwbvh_level_steps.h):
// each step discovers a level, scans the inner counts in level order over
// the level's bound, writes the next level's record and enqueues; the host
// waits only for the lagging copy of a record (launch_in_lagged_rounds),
// then reads the records once. cap: the wide nodes the arrays hold.
std::vector<WideLevel> discover_levels(CwbvhArrays& a, const cwbvh::EmitView& view, uint32_t cap,
                                       LaggedCopies<cwbvh::LevelRecord>& copies) {
    RF_CUDA_CHECK(cudaMemsetAsync(a.inner_count.data(), 0, size_t{cap} * sizeof(uint32_t)));  // zeros past the levels
    RF_CUDA_CHECK(cudaMemsetAsync(a.level_records.data(), 0, a.level_records.bytes()));
    launch_shaped(cwbvh_first_level_kernel, {1, 1}, a.level_records.data());
    const auto step = [&](uint32_t level, const cwbvh::LevelRecord*, uint32_t) {
        const uint32_t width = cwbvh::level_width_bound(level, cap);
        launch(cwbvh_discover_kernel, width, view, a.level_records.data(), level, width);
        cub_run(a.scan_scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceScan::ExclusiveSum(temp, bytes, a.inner_count.data(), a.level_prefix.data(),
                                                 cwbvh::nodes_through_level_bound(level, cap));
        });
        launch_shaped(cwbvh_next_level_kernel, {1, 1}, a.level_prefix.data(), a.inner_count.data(),
                      a.level_records.data(), level, cap, a.counters.data() + 1);
        launch(cwbvh_enqueue_kernel, width, view, a.level_records.data(), level, a.level_prefix.data(), width);
    };
    const uint32_t launched = launch_in_lagged_rounds(
        copies, kLevelsPerRound, uint32_t(kCwbvhMaxDepth), step,
        [&](uint32_t steps) { return a.level_records.data() + steps; },
        [](const cwbvh::LevelRecord& next) { return next.count == 0; });
    const std::vector<cwbvh::LevelRecord> records = download_all(a.level_records, size_t{launched} + 1);
    std::vector<WideLevel> levels;
    for (const cwbvh::LevelRecord& r : records) {
        if (r.count == 0) return levels;
        levels.push_back({r.start, r.count});
    }
    throw Error("build_cwbvh: wide BVH deeper than " + std::to_string(kCwbvhMaxDepth) + " levels");
}

// CWBVH 4-5: subtree counts bottom up, then the emission top down.
void total_and_emit(const std::vector<WideLevel>& levels, const cwbvh::EmitView& view) {
    for (size_t l = levels.size(); l-- > 0;) launch(cwbvh_totals_kernel, levels[l].count, view, levels[l].start,
                                                   levels[l].count);
    for (const WideLevel& level : levels) launch(cwbvh_emit_kernel, level.count, view, level.start, level.count);
}

// CWBVH 0-5 over `input` (the arrays sized for it: n refined nodes, one
// refined leaf per reference), the kernels timed into device_ms; returns
// the number of wide levels.
size_t run_cwbvh(const DeviceCanonicalView& input, uint32_t n, size_t references, CwbvhArrays& a,
                 double* device_ms) {
    EventTimer timer;
    LaggedCopies<cwbvh::LevelRecord> copies;  // pinned: allocated before the timed kernels
    const cwbvh::EmitView view = a.view(input.triangles);
    // Wide nodes at most: one per refined inner node (the root alone when it is a leaf).
    const auto cap = static_cast<uint32_t>(std::clamp<size_t>(references, 1, n));
    timer.start();
    refine_leaves(input, a);
    solve_collapse(a, n);
    const std::vector<WideLevel> levels = discover_levels(a, view, cap, copies);
    total_and_emit(levels, view);
    const double ms = timer.stop_ms();
    if (device_ms) *device_ms = ms;
    return levels.size();
}

// The wide tree's size after the device's consistency checks (two small copies).
struct CwbvhSize {
    uint32_t nodes = 0;
    size_t leaf_slots = 0;
};

CwbvhSize checked_cwbvh_size(const CwbvhArrays& a, uint32_t n, size_t references) {
    const cwbvh::OwnCounts total = download_value(a.subtree.data());
    const std::vector<uint32_t> counts = download_all(a.counters, 2);
    if (counts[1] & cwbvh::kErrorQuantize)
        throw Error("build_cwbvh: a box cannot be quantised (coordinates too large)");
    if ((counts[1] & cwbvh::kErrorLevelOverflow) || total.triangles != references || total.inner + 1u > n)
        throw Error("build_cwbvh_on_device: inconsistent wide tree (device error)");
    return {total.inner + 1u, counts[0]};
}

// The wide BVH back to the host.
CwbvhBvh download_cwbvh(const CwbvhArrays& a, uint32_t n, size_t references, size_t depth) {
    const CwbvhSize size = checked_cwbvh_size(a, n, references);
    CwbvhBvh out;
    out.nodes = download_all(a.out_nodes, size.nodes);
    out.triangles = download_all(a.out_tris, references);
    out.leaf_count = size.leaf_slots;
    out.depth = static_cast<int>(depth);
    return out;
}

// Node pairs 1-3 over `input` into out_nodes and out_lists (sized for
// `expected`), the kernels timed into device_ms; rf::Error unless the
// device's root sizes are `expected` (one 16-byte copy).
void run_aila_laine(const DeviceCanonicalView& input, const aila_laine::SubtreeSize& expected,
                    AilaLaineNode* out_nodes, AilaLaineFloat4* out_lists, MemoryMeter& meter, double* device_ms) {
    const uint32_t n = input.node_count;
    DeviceBuffer<uint32_t> parent(meter, "node pairs: parents", n), arrivals(meter, "node pairs: arrival counters", n);
    DeviceBuffer<aila_laine::SubtreeSize> size(meter, "node pairs: subtree sizes", n);
    EventTimer timer;
    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(parent.data(), 0xFF, parent.bytes()));  // root: kNoParent
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    launch(aila_laine_parents_kernel, n, input.nodes, n, parent.data());
    launch(aila_laine_sizes_kernel, n, input.nodes, n, parent.data(), size.data(), arrivals.data());
    launch(aila_laine_emit_kernel, n, input.nodes, n, parent.data(), size.data(), input.prim_indices,
           input.triangles, out_nodes, out_lists);
    const double ms = timer.stop_ms();
    if (device_ms) *device_ms = ms;
    const aila_laine::SubtreeSize root = download_value(size.data());
    if (root.inner_nodes != expected.inner_nodes || root.float4s != expected.float4s ||
        root.leaves != expected.leaves || root.triangle_refs != expected.triangle_refs)
        throw Error("convert_to_aila_laine_on_device: inconsistent subtree sizes (device error or malformed BVH)");
}

void check_aila_laine_links(size_t inner, size_t float4s) {
    constexpr size_t kMaxLink = static_cast<size_t>(kAilaLaineEntrySentinel);
    if (inner >= kMaxLink) throw Error("convert_to_aila_laine: too many nodes for 31-bit links");
    if (float4s > kMaxLink) throw Error("convert_to_aila_laine: too many leaf triangles for 31-bit links");
}

}  // namespace

AilaLaineBvh convert_to_aila_laine_on_device(const Bvh& bvh, std::span<const Triangle> triangles,
                                             double* device_ms, int device) {
    if (device_ms) *device_ms = 0.0;
    AilaLaineBvh out;
    if (bvh.nodes.empty()) return out;
    const CanonicalTotals checked = validate_canonical(bvh, triangles.size(), "convert_to_aila_laine", kBvhMaxDepth);
    check_aila_laine_links(checked.inner, checked.aila_laine_float4s);
    const aila_laine::SubtreeSize total{uint32_t(checked.inner), uint32_t(checked.aila_laine_float4s),
                                        uint32_t(checked.leaves), uint32_t(checked.references)};
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    MemoryMeter meter;
    const CanonicalOnDevice input(bvh, triangles, meter, "node pairs");
    DeviceBuffer<AilaLaineNode> out_nodes(meter, "node pairs: nodes", total.inner_nodes);
    DeviceBuffer<AilaLaineFloat4> out_tris(meter, "node pairs: leaf lists", total.float4s);
    run_aila_laine(input.view(), total, out_nodes.data(), out_tris.data(), meter, device_ms);

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
    if (bvh.nodes.empty()) return {};
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
    const CanonicalOnDevice input(bvh, triangles, meter, "CWBVH");
    CwbvhArrays arrays(meter, canonical_count, n, checked.refined_extra, references);
    const size_t depth = run_cwbvh(input.view(), n, references, arrays, device_ms);
    return download_cwbvh(arrays, n, references, depth);
}

ResidentAilaLaine convert_to_aila_laine_resident(const DeviceCanonicalView& in, DeviceBuffer<AilaLaineNode>& nodes,
                                                 DeviceBuffer<AilaLaineFloat4>& leaf_lists, double* device_ms,
                                                 int device) {
    if (device_ms) *device_ms = 0.0;
    ResidentAilaLaine out;
    nodes.release();
    leaf_lists.release();
    if (in.node_count == 0) return out;
    // A builder's tree: every inner node has two children, every reference one leaf.
    if (in.node_count % 2 == 0) throw Error("convert_to_aila_laine_on_device: an even node count is no binary tree");
    const size_t leaves = (size_t{in.node_count} + 1) / 2, inner = leaves - 1;
    const size_t float4s = in.prim_count * size_t{kAilaLaineTriangleStride} + leaves;
    check_aila_laine_links(inner, float4s);
    const aila_laine::SubtreeSize total{uint32_t(inner), uint32_t(float4s), uint32_t(leaves),
                                        uint32_t(in.prim_count)};
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    MemoryMeter meter;
    nodes.allocate(inner);
    leaf_lists.allocate(float4s);
    run_aila_laine(in, total, nodes.data(), leaf_lists.data(), meter, device_ms);
    out.root = inner == 0 ? ~int32_t{0} : 0;
    out.node_count = uint32_t(inner);
    out.float4s = float4s;
    out.leaf_count = leaves;
    out.triangle_refs = in.prim_count;
    return out;
}

ResidentCwbvh build_cwbvh_resident(const DeviceCanonicalView& in, DeviceBuffer<CwbvhNode>& nodes,
                                   DeviceBuffer<CwbvhTriangle>& triangles, double* device_ms, int device) {
    if (device_ms) *device_ms = 0.0;
    ResidentCwbvh out;
    nodes.release();
    triangles.release();
    if (in.node_count == 0) return out;
    // Below 2^31 references the refined total (at most 2 per reference) fits the device's 32-bit sum.
    if (in.prim_count >= size_t{0x7FFFFFFF}) throw Error("build_cwbvh: too many triangle references");
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    MemoryMeter meter;
    const size_t refined_extra = refined_extra_on_device(in, meter);
    if (size_t{in.node_count} + refined_extra >= std::numeric_limits<uint32_t>::max())
        throw Error("build_cwbvh: too many nodes after leaf refinement");
    const auto n = static_cast<uint32_t>(in.node_count + refined_extra);
    CwbvhArrays arrays(meter, in.node_count, n, refined_extra, in.prim_count);
    const size_t depth = run_cwbvh(in, n, in.prim_count, arrays, device_ms);
    const CwbvhSize size = checked_cwbvh_size(arrays, n, in.prim_count);
    // Device to device into the caller's exact-size buffers (the arrays are
    // sized by upper bounds and freed on return).
    nodes.allocate(size.nodes);
    triangles.allocate(in.prim_count);
    RF_CUDA_CHECK(cudaMemcpy(nodes.data(), arrays.out_nodes.data(), nodes.bytes(), cudaMemcpyDeviceToDevice));
    RF_CUDA_CHECK(
        cudaMemcpy(triangles.data(), arrays.out_tris.data(), triangles.bytes(), cudaMemcpyDeviceToDevice));
    out.node_count = size.nodes;
    out.triangle_count = uint32_t(in.prim_count);
    out.leaf_count = size.leaf_slots;
    out.depth = static_cast<int>(depth);
    return out;
}

namespace {

// The resident chain as DeviceTracer runs it: the tree built and kept on
// the device, the tracer's triangles uploaded after the build.
struct ResidentInput {
    DeviceBvh bvh;
    DeviceBuffer<Triangle> triangles{"resident chain: triangles"};
    ResidentInput(std::span<const Triangle> tris, const BuildOptions& options, int device) {
        require_device(device);
        RF_CUDA_CHECK(cudaSetDevice(device));
        DeviceBuildStages stages;
        bvh = build_resident_bvh(tris, options, stages, device);
        triangles.upload(tris);
    }
    [[nodiscard]] DeviceCanonicalView view() const {
        return canonical_view(bvh, triangles.data(), triangles.size());
    }
};

}  // namespace

AilaLaineBvh resident_aila_laine_on_device(std::span<const Triangle> triangles, const BuildOptions& options,
                                           int device) {
    const ResidentInput input(triangles, options, device);
    DeviceBuffer<AilaLaineNode> nodes("resident chain: node pairs");
    DeviceBuffer<AilaLaineFloat4> lists("resident chain: leaf lists");
    const ResidentAilaLaine r = convert_to_aila_laine_resident(input.view(), nodes, lists, nullptr, device);
    AilaLaineBvh out;
    out.nodes = download_all(nodes, r.node_count);
    out.triangles = download_all(lists, r.float4s);
    if (!input.bvh.empty()) out.bounds = download_value(input.bvh.nodes.data()).bounds;
    out.root = r.root;
    out.leaf_count = r.leaf_count;
    out.triangle_refs = r.triangle_refs;
    return out;
}

CwbvhBvh resident_cwbvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, int device) {
    const ResidentInput input(triangles, options, device);
    DeviceBuffer<CwbvhNode> nodes("resident chain: CWBVH nodes");
    DeviceBuffer<CwbvhTriangle> tris("resident chain: CWBVH triangles");
    const ResidentCwbvh r = build_cwbvh_resident(input.view(), nodes, tris, nullptr, device);
    CwbvhBvh out;
    out.nodes = download_all(nodes, r.node_count);
    out.triangles = download_all(tris, r.triangle_count);
    out.leaf_count = r.leaf_count;
    out.depth = r.depth;
    return out;
}

}  // namespace rf::cuda
