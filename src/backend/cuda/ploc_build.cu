// PLOC on the device (Meister and Bittner 2018, "Parallel Locally-Ordered
// Clustering for Bounding Volume Hierarchy Construction", IEEE TVCG),
// building rf::build_ploc's tree:
//  1. boxes, bounds, 63-bit Morton codes and ONE stable radix sort
//     (morton_sort.cu, shared with the LBVH and HLBVH2).
//  2. the initial clusters: one thread per sorted position writes its leaf
//     reference and gathers its triangle's box.
//  3. per iteration until one cluster is left (sec. 4), over the shared
//     per-cluster steps of accel/bvh/builders/ploc_steps.h, with no host
//     round trip per iteration: the loop state (count, nodes made,
//     iterations, a fault) lives on the device, every kernel reads it and
//     one thread advances it (ploc::commit_iteration). Two phases:
//     GRID PHASE, while the clusters exceed the single block's capacity:
//     a. nearest neighbours (sec. 4.2): one block per 256 clusters loads their
//        boxes and radius more on each side into shared memory; every pair
//        with an end in the block is evaluated once (window_pairs_from) and
//        offered to both ends by a 64-bit atomicMin on shared keys (area,
//        then the tie rule), so the result does not depend on the order of
//        the atomics. Radii too large for shared memory: one thread per
//        cluster searches global memory (nearest_neighbour).
//     b. the (survivor, merge) flags' exclusive prefix sum (sec. 4.3: new
//        positions and node numbers in cluster order, as the CPU numbers
//        them) in three passes: block sums, one block scanning them (and
//        advancing the state), and per block its own scan plus its offset,
//     c. fused with the merge and compaction (compact_cluster): the lower
//        end of a mutual pair writes the new node (children, box) and puts it
//        at its position; other survivors move.
//     The host launches these in rounds sized by a lagging, asynchronous
//     copy of the count (grids for an upper bound; blocks past the count
//     exit; an iteration that belongs to the tail is a no-op). A CUDA graph
//     with a conditional WHILE node would drop even that copy, but it
//     cannot be checked without a device here; the fixed schedule runs the
//     same kernels and its logic is replayed on the CPU.
//     TAIL (at most kTailMaxClusters clusters): all remaining iterations in
//     ONE block, the clusters in shared memory, __syncthreads between the
//     neighbour, scan and compaction steps (the same steps, one window over
//     all clusters, per-thread chunks scanned in cluster order).
//     The final state comes back once: a fault (no progress) is an error.
//  4. emission on the device (raw_tree_emit.cu): boxes, counts, SAH costs
//     and leaf collapse bottom-up, the canonical layout, and the BVH back to
//     the host; so the triangle boxes stay until then. A tree deeper than
//     kBvhMaxDepth comes back raw (order, children, nodes per iteration) and
//     the host refits and emits it (emit_ploc_tree, the CPU PLOC's own).
//     Either way the BVH is build_ploc's.
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter
// and live in the scope of the stages that use them.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/ploc_emit.h"
#include "accel/bvh/builders/ploc_steps.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/lagged_rounds.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/ploc_build.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

// kBlockSize (launch.h) is also the clusters per neighbour window.
constexpr uint32_t kMaxWindowRadius = 256;  // beyond this the window would not fit in shared memory
constexpr uint32_t kScanThreads = 1024;     // the one block that scans the block sums
constexpr uint32_t kTailThreads = 1024;     // the single-block tail's threads
// The tail's clusters at most: 68 bytes each (key, both sides' box and
// reference, neighbour), 204 KiB of the 227 KiB of shared memory an sm_90
// block may opt into. Clusters fall geometrically per iteration, so the
// grid phase runs about a dozen iterations for a million triangles and the
// tail the remaining forty to fifty.
constexpr uint32_t kTailMaxClusters = 3072;
// Grid iterations launched between two looks at the count (one lagging,
// asynchronous copy per round).
constexpr uint32_t kIterationsPerRound = 3;

size_t window_shared_bytes(uint32_t radius) {
    return kBlockSize * sizeof(uint64_t) + (kBlockSize + 2 * size_t{radius}) * sizeof(Box3f);
}

// Stage 2: the sorted triangles as the first clusters.
__global__ void initial_clusters_kernel(const Box3f* triangle_boxes, const uint32_t* order, uint32_t n, uint32_t* refs,
                                        Box3f* boxes) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    refs[i] = ploc::kLeafRef | i;
    boxes[i] = triangle_boxes[order[i]];
}

// The minimum of the keys offered to a block's clusters, in shared memory.
struct SharedMinimum {
    uint64_t* keys;
    __device__ void operator()(uint32_t slot, uint64_t key) const {
        atomicMin(reinterpret_cast<unsigned long long*>(keys + slot), static_cast<unsigned long long>(key));
    }
};

// The ping-pong cluster buffers; an iteration reads the side its parity picks.
struct ClusterPair {
    uint32_t* refs[2];
    Box3f* boxes[2];
};

// Iteration `iterations`' clusters, the next iteration's and the tree.
__device__ ploc::ClusterArrays iteration_arrays(const ClusterPair& c, uint32_t iterations, uint32_t* children,
                                                Box3f* node_boxes) {
    const uint32_t from = iterations & 1u;
    return ploc::ClusterArrays{c.refs[from], c.boxes[from], c.refs[1 - from], c.boxes[1 - from], children, node_boxes};
}

// The grid-wide kernels of an iteration are launched before its cluster
// count is known on the host (grids sized for an upper bound): each reads
// the count from the loop state and its blocks past it, or every block when
// the iteration belongs to the single-block tail, exit.
__device__ bool grid_block_idle(const ploc::LoopState& s, uint32_t tail_capacity) {
    return !ploc::grid_iteration_runs(s, tail_capacity) || blockIdx.x * kBlockSize >= s.count;
}

// Stage 3a, the paper's shared-memory window: one block per kBlockSize
// clusters; dynamic shared memory holds their keys, then the window's boxes.
__global__ void __launch_bounds__(kBlockSize)
    window_neighbours_kernel(ClusterPair clusters, const ploc::LoopState* state, uint32_t tail_capacity,
                             uint32_t radius, uint32_t* neighbour) {
    const ploc::LoopState s = *state;
    if (grid_block_idle(s, tail_capacity)) return;
    const Box3f* boxes = clusters.boxes[s.iterations & 1u];
    extern __shared__ uint64_t shared_words[];
    uint64_t* keys = shared_words;
    Box3f* window_boxes = reinterpret_cast<Box3f*>(keys + kBlockSize);
    const ploc::Window w = ploc::block_window(blockIdx.x * kBlockSize, kBlockSize, s.count, radius);
    keys[threadIdx.x] = ploc::kNoNeighbour;
    for (uint32_t p = w.begin + threadIdx.x; p < w.end; p += kBlockSize) window_boxes[p - w.begin] = boxes[p];
    __syncthreads();
    SharedMinimum record{keys};
    for (uint32_t p = w.begin + threadIdx.x; p < w.block_end; p += kBlockSize) {
        ploc::window_pairs_from(window_boxes, w, radius, p, record);
    }
    __syncthreads();
    const uint32_t i = w.block_begin + threadIdx.x;
    if (i < w.block_end) neighbour[i] = ploc::neighbour_from_key(i, keys[threadIdx.x]);
}

// Stage 3a for large radii: one thread per cluster over global memory.
__global__ void neighbours_kernel(ClusterPair clusters, const ploc::LoopState* state, uint32_t tail_capacity,
                                  uint32_t radius, uint32_t* neighbour) {
    const ploc::LoopState s = *state;
    if (grid_block_idle(s, tail_capacity)) return;
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < s.count) neighbour[i] = ploc::nearest_neighbour(clusters.boxes[s.iterations & 1u], s.count, radius, i);
}

// Stage 3b, first pass: each block's sum of its clusters' compaction flags.
__global__ void __launch_bounds__(kBlockSize)
    block_flag_sums_kernel(const uint32_t* neighbour, const ploc::LoopState* state, uint32_t tail_capacity,
                           uint64_t* block_sums) {
    using Reduce = cub::BlockReduce<uint64_t, kBlockSize>;
    __shared__ typename Reduce::TempStorage storage;
    const ploc::LoopState s = *state;
    if (grid_block_idle(s, tail_capacity)) return;
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    const uint64_t total = Reduce(storage).Sum(i < s.count ? ploc::compaction_flags(neighbour, i) : uint64_t{0});
    if (threadIdx.x == 0) block_sums[blockIdx.x] = total;
}

// Stage 3b, second pass, one block: the block sums become their exclusive
// prefix sums (in place, contiguous chunks per thread), and the total
// advances the loop state into `next` (the iteration's kernels read `state`,
// so it is not overwritten under them). A tail iteration passes the state on.
__global__ void __launch_bounds__(kScanThreads)
    scan_block_sums_kernel(const ploc::LoopState* state, uint32_t tail_capacity, uint64_t* block_sums,
                           uint32_t* iteration_nodes, ploc::LoopState* next) {
    using Scan = cub::BlockScan<uint64_t, kScanThreads>;
    __shared__ typename Scan::TempStorage storage;
    const ploc::LoopState s = *state;
    if (!ploc::grid_iteration_runs(s, tail_capacity)) {
        if (threadIdx.x == 0) *next = s;
        return;
    }
    const ploc::Chunk c = ploc::thread_chunk((s.count + kBlockSize - 1) / kBlockSize, kScanThreads, threadIdx.x);
    uint64_t sum = 0;
    for (uint32_t b = c.begin; b < c.end; ++b) sum += block_sums[b];
    uint64_t offset, total;
    Scan(storage).ExclusiveSum(sum, offset, total);
    for (uint32_t b = c.begin; b < c.end; ++b) {
        const uint64_t own = block_sums[b];
        block_sums[b] = offset;
        offset += own;
    }
    if (threadIdx.x == 0) *next = ploc::commit_iteration(s, total, iteration_nodes);
}

// Stage 3c: one thread per cluster; its prefix is its block's offset plus
// the block's own exclusive scan of the flags.
__global__ void __launch_bounds__(kBlockSize)
    compact_kernel(ClusterPair clusters, const uint32_t* neighbour, const uint64_t* block_offsets,
                   const ploc::LoopState* state, uint32_t tail_capacity, uint32_t* children, Box3f* node_boxes) {
    using Scan = cub::BlockScan<uint64_t, kBlockSize>;
    __shared__ typename Scan::TempStorage storage;
    const ploc::LoopState s = *state;
    if (grid_block_idle(s, tail_capacity)) return;
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    uint64_t prefix;
    Scan(storage).ExclusiveSum(i < s.count ? ploc::compaction_flags(neighbour, i) : uint64_t{0}, prefix);
    if (i < s.count) {
        ploc::compact_cluster(iteration_arrays(clusters, s.iterations, children, node_boxes), neighbour, i,
                              block_offsets[blockIdx.x] + prefix, s.next_node);
    }
}

// The single-block tail's shared memory for `capacity` clusters: the
// neighbour keys, both sides of the clusters, the neighbours.
struct TailShared {
    uint64_t* keys;
    Box3f* boxes[2];
    uint32_t* refs[2];
    uint32_t* neighbour;
};

constexpr size_t kTailBytesPerCluster = sizeof(uint64_t) + 2 * (sizeof(Box3f) + sizeof(uint32_t)) + sizeof(uint32_t);

__device__ TailShared tail_layout(uint64_t* words, uint32_t capacity) {
    TailShared t;
    t.keys = words;
    t.boxes[0] = reinterpret_cast<Box3f*>(words + capacity);
    t.boxes[1] = t.boxes[0] + capacity;
    t.refs[0] = reinterpret_cast<uint32_t*>(t.boxes[1] + capacity);
    t.refs[1] = t.refs[0] + capacity;
    t.neighbour = t.refs[1] + capacity;
    return t;
}

// Stage 3, the last iterations (at most `capacity` clusters) in one block:
// the clusters stay in shared memory, the whole cluster array is one window
// (every pair within the radius evaluated once, any radius), and the
// compaction scans per-thread chunks in cluster order; __syncthreads
// separates the steps. The same steps and numbering as the grid iterations.
__global__ void __launch_bounds__(kTailThreads)
    tail_kernel(ClusterPair clusters, const ploc::LoopState* state, uint32_t capacity, uint32_t radius,
                uint32_t* children, Box3f* node_boxes, uint32_t* iteration_nodes, ploc::LoopState* final_state) {
    using Scan = cub::BlockScan<uint64_t, kTailThreads>;
    __shared__ typename Scan::TempStorage storage;
    extern __shared__ uint64_t shared_words[];
    const TailShared t = tail_layout(shared_words, capacity);
    ploc::LoopState s = ploc::tail_start(*state, capacity);
    if (s.fault != 0) {
        if (threadIdx.x == 0) *final_state = s;
        return;
    }
    const uint32_t from = s.iterations & 1u;
    for (uint32_t i = threadIdx.x; i < s.count; i += kTailThreads) {
        t.refs[0][i] = clusters.refs[from][i];
        t.boxes[0][i] = clusters.boxes[from][i];
    }
    __syncthreads();
    for (uint32_t side = 0; s.count > 1; side ^= 1u) {
        const uint32_t count = s.count;
        for (uint32_t i = threadIdx.x; i < count; i += kTailThreads) t.keys[i] = ploc::kNoNeighbour;
        __syncthreads();
        const ploc::Window w = ploc::block_window(0, count, count, radius);
        SharedMinimum record{t.keys};
        for (uint32_t p = threadIdx.x; p < count; p += kTailThreads) {
            ploc::window_pairs_from(t.boxes[side], w, radius, p, record);
        }
        __syncthreads();
        for (uint32_t i = threadIdx.x; i < count; i += kTailThreads) t.neighbour[i] = ploc::neighbour_from_key(i, t.keys[i]);
        __syncthreads();
        const ploc::Chunk c = ploc::thread_chunk(count, kTailThreads, threadIdx.x);
        uint64_t sum = 0;
        for (uint32_t i = c.begin; i < c.end; ++i) sum += ploc::compaction_flags(t.neighbour, i);
        uint64_t prefix, total;
        Scan(storage).ExclusiveSum(sum, prefix, total);
        const ploc::ClusterArrays arrays{t.refs[side], t.boxes[side], t.refs[1 - side], t.boxes[1 - side],
                                         children,     node_boxes};
        for (uint32_t i = c.begin; i < c.end; ++i) {
            ploc::compact_cluster(arrays, t.neighbour, i, prefix, s.next_node);
            prefix += ploc::compaction_flags(t.neighbour, i);
        }
        s = ploc::commit_iteration(s, total, threadIdx.x == 0 ? iteration_nodes : nullptr);  // the same in every thread
        if (s.fault != 0) break;
        __syncthreads();  // the next side is written; the scan's storage is free again
    }
    if (threadIdx.x == 0) *final_state = s;
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The clusters, ping-ponged by the iterations: references and boxes.
struct ClusterBuffers {
    DeviceBuffer<uint32_t> refs[2];
    DeviceBuffer<Box3f> boxes[2];
};

// What the clustering leaves: the nodes, in creation order.
struct PlocNodes {
    DeviceBuffer<uint32_t> children;         // 2 (n - 1)
    DeviceBuffer<Box3f> boxes;               // raw trees only: n - 1, as the merges wrote them
    DeviceBuffer<uint32_t> iteration_nodes;  // nodes made per iteration (at most n - 1 iterations)
    uint32_t iterations = 0;
};

// Stage 2: the sorted triangles as the first clusters.
ClusterBuffers first_clusters(const DeviceMortonOrder<uint64_t>& sorted, uint32_t n, BuildContext& build) {
    ClusterBuffers clusters{{DeviceBuffer<uint32_t>(build.meter, "PLOC: cluster references", n),
                             DeviceBuffer<uint32_t>(build.meter, "PLOC: next cluster references", n)},
                            {DeviceBuffer<Box3f>(build.meter, "PLOC: cluster boxes", n),
                             DeviceBuffer<Box3f>(build.meter, "PLOC: next cluster boxes", n)}};
    build.timer.start();
    launch(initial_clusters_kernel, n, sorted.boxes.data(), sorted.order.data(), n, clusters.refs[0].data(),
           clusters.boxes[0].data());
    build.stages.ploc_ms = build.timer.stop_ms();
    return clusters;
}

// What the iterations work in, sized for the first (n clusters).
struct LoopArrays {
    DeviceBuffer<uint32_t> neighbour;       // per cluster
    DeviceBuffer<uint64_t> block_sums;      // per block of clusters: flag sums, then their offsets
    DeviceBuffer<ploc::LoopState> states;   // 2: an iteration reads one and advances it into the other
    LaggedCopies<ploc::LoopState> copies;   // the host's lagging looks at the state
};

// The clusters the single-block tail holds: kTailMaxClusters, or fewer
// where the device's opt-in shared memory per block is smaller.
uint32_t tail_capacity() {
    int device = 0, optin = 0;
    RF_CUDA_CHECK(cudaGetDevice(&device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, device));
    cudaFuncAttributes attributes{};
    RF_CUDA_CHECK(cudaFuncGetAttributes(&attributes, tail_kernel));
    const size_t room = size_t(optin) > attributes.sharedSizeBytes ? size_t(optin) - attributes.sharedSizeBytes : 0;
    const size_t fits = room / kTailBytesPerCluster;
    if (fits < 2) throw Error("PLOC on the device: shared memory too small for the single-block tail");
    return static_cast<uint32_t>(std::min<size_t>(fits, kTailMaxClusters));
}

// Launches iteration `launched` of the grid phase, its grids sized for at
// most `bound` clusters; its kernels read the count from states[launched % 2].
void launch_grid_iteration(const ClusterPair& clusters, uint32_t launched, uint32_t bound, uint32_t radius,
                           uint32_t tail, LoopArrays& work, PlocNodes& nodes) {
    const ploc::LoopState* state = work.states.data() + (launched & 1);
    ploc::LoopState* next = work.states.data() + ((launched + 1) & 1);
    uint32_t* neighbour = work.neighbour.data();
    if (radius <= kMaxWindowRadius) {
        launch_shaped(window_neighbours_kernel, {blocks_for(bound), kBlockSize, window_shared_bytes(radius)},
                      clusters, state, tail, radius, neighbour);
    } else {
        launch(neighbours_kernel, bound, clusters, state, tail, radius, neighbour);
    }
    launch(block_flag_sums_kernel, bound, neighbour, state, tail, work.block_sums.data());
    launch_shaped(scan_block_sums_kernel, {1, kScanThreads}, state, tail, work.block_sums.data(),
                  nodes.iteration_nodes.data(), next);
    launch(compact_kernel, bound, clusters, neighbour, work.block_sums.data(), state, tail, nodes.children.data(),
           nodes.boxes.data());
}

// Stage 3, the grid phase: rounds of kIterationsPerRound iterations
// launched back to back (lagged_rounds.h), none waiting for the host; the
// host stops once a lagging copy of the state shows at most `tail`
// clusters (the iterations in flight then finish as no-ops), and sizes
// later grids by the count it saw. Returns the iterations launched.
uint32_t run_grid_phase(const ClusterPair& clusters, uint32_t n, uint32_t radius, uint32_t tail, LoopArrays& work,
                        PlocNodes& nodes) {
    return launch_in_lagged_rounds<ploc::LoopState>(
        work.copies, kIterationsPerRound, n,  // every real iteration merges: fewer than n of them
        [&](uint32_t launched, const ploc::LoopState* seen, uint32_t) {
            launch_grid_iteration(clusters, launched, seen != nullptr ? seen->count : n, radius, tail, work, nodes);
        },
        [&](uint32_t launched) { return work.states.data() + (launched & 1); },
        [&](const ploc::LoopState& s) { return !ploc::grid_iteration_runs(s, tail); });
}

// The iterations' fault as an error.
[[noreturn]] void throw_loop_fault(const ploc::LoopState& s, uint32_t tail) {
    if (s.fault == ploc::kFaultTailOverflow) {
        throw Error("PLOC on the device: the single-block tail got " + std::to_string(s.fault_survivors) +
                    " clusters, more than its " + std::to_string(tail));
    }
    throw Error("PLOC on the device: iteration " + std::to_string(s.iterations) + " kept " +
                std::to_string(s.fault_survivors) + " of " + std::to_string(s.count) + " clusters with " +
                std::to_string(s.fault_merges) + " merges");
}

// Stage 3: iterations until one cluster is left, timed as one, with no
// host round trip per iteration: the grid phase while the clusters exceed
// the single block's capacity, then the tail in one launch. The final
// state comes back once; the iterations' arrays are freed on return.
void merge_until_one(ClusterBuffers& buffers, uint32_t n, uint32_t radius, PlocNodes& nodes, BuildContext& build) {
    LoopArrays work{DeviceBuffer<uint32_t>(build.meter, "PLOC: nearest neighbours", n),
                    DeviceBuffer<uint64_t>(build.meter, "PLOC: block flag sums", blocks_for(n)),
                    DeviceBuffer<ploc::LoopState>(build.meter, "PLOC: loop states", 2),
                    {}};  // the pinned slots and events, made before the timed stage
    const ClusterPair clusters{{buffers.refs[0].data(), buffers.refs[1].data()},
                               {buffers.boxes[0].data(), buffers.boxes[1].data()}};
    const uint32_t tail = tail_capacity();
    const uint32_t tail_clusters = std::min(n, tail);
    RF_CUDA_CHECK(cudaFuncSetAttribute(tail_kernel, cudaFuncAttributeMaxDynamicSharedMemorySize,
                                       static_cast<int>(tail_clusters * kTailBytesPerCluster)));
    const ploc::LoopState first = ploc::first_state(n);
    RF_CUDA_CHECK(cudaMemcpy(work.states.data(), &first, sizeof first, cudaMemcpyHostToDevice));

    build.timer.start();
    const uint32_t launched = n > tail ? run_grid_phase(clusters, n, radius, tail, work, nodes) : 0;
    ploc::LoopState* final_state = work.states.data() + ((launched + 1) & 1);
    launch_shaped(tail_kernel, {1, kTailThreads, tail_clusters * kTailBytesPerCluster}, clusters,
                  work.states.data() + (launched & 1), tail_clusters, radius, nodes.children.data(),
                  nodes.boxes.data(), nodes.iteration_nodes.data(), final_state);
    build.stages.ploc_ms += build.timer.stop_ms();

    const ploc::LoopState last = download_value(final_state);
    if (last.fault != 0) throw_loop_fault(last, tail_clusters);
    if (last.count != 1 || last.next_node != n - 1) {
        throw Error("PLOC on the device: " + std::to_string(last.count) + " clusters and " +
                    std::to_string(last.next_node) + " nodes left, not one root over " + std::to_string(n - 1));
    }
    nodes.iterations = last.iterations;
    build.stages.ploc_iterations = last.iterations;
    build.stages.peak_device_bytes = build.meter.peak();
}

// Stages 2-3: the clustering of the sorted triangles; the clusters are
// freed on return. Raw trees keep the node boxes instead of the triangle
// boxes, which only the device emission reads after the first clusters.
PlocNodes cluster(DeviceMortonOrder<uint64_t>& sorted, uint32_t n, uint32_t radius, bool raw, BuildContext& build) {
    ClusterBuffers clusters = first_clusters(sorted, n, build);
    if (raw) sorted.boxes.release();
    PlocNodes nodes{DeviceBuffer<uint32_t>(build.meter, "PLOC: child references", 2 * size_t{n - 1}),
                    DeviceBuffer<Box3f>(build.meter, "PLOC: node boxes", raw ? n - 1 : 0),
                    DeviceBuffer<uint32_t>(build.meter, "PLOC: nodes per iteration", n - 1)};
    merge_until_one(clusters, n, radius, nodes, build);
    return nodes;
}

// The device pipeline for n >= 2 triangles. `raw`: the node boxes are kept
// and the raw tree comes back. Otherwise, with `config`, the device emits
// the BVH into `bvh` and returns true; false when the tree was too deep, and
// then the raw tree came back in `out`.
bool build_on_device(std::span<const Triangle> triangles, uint32_t radius, DeviceBuildStages& stages,
                     DevicePlocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
                     DeviceBvh* resident = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    BuildContext build(stages);
    build.resident = resident;
    // 1. Boxes, centroid bounds, 63-bit Morton codes, the sort (morton_sort.cu).
    DeviceMortonOrder<uint64_t> sorted = sort_triangles_by_morton_codes<uint64_t>(triangles, "PLOC", build);
    sorted.keys.release();  // the order is all the clustering needs
    // 2-3. The clustering.
    const PlocNodes nodes = cluster(sorted, n, radius, raw, build);

    // 4. Emission on the device.
    if (!raw) {
        DeviceRawTree tree;
        tree.children = nodes.children.data();
        tree.node_slots = n - 1;
        tree.root = n - 2;
        tree.primitives = n;
        tree.boxes = sorted.boxes.data();
        tree.boxes_by_triangle = true;
        tree.order = sorted.order.data();
        if (emit_raw_tree_on_device(tree, *config, "PLOC", build, *bvh)) return true;
    }

    // The clustering back to the host.
    build.timer.start();
    out.order = download_all(sorted.order, n);
    out.children = download_all(nodes.children, 2 * size_t{n - 1});
    out.iteration_nodes = download_all(nodes.iteration_nodes, nodes.iterations);
    if (raw) out.node_boxes = download_all(nodes.boxes, n - 1);
    build.stages.download_ms += build.timer.stop_ms();
    return false;
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, int radius, DeviceBuildStages& stages, int device,
               DevicePlocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
               DeviceBvh* resident = nullptr) {
    if (triangles.size() >= ploc::kLeafRef) throw Error("PLOC on the device: more than 2^31-1 triangles");
    const size_t n = triangles.size();
    if (n < 2) {  // no merges: nothing for the device to do
        out.order.assign(n, 0u);
        return false;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    return build_on_device(triangles, ploc::clamp_radius(radius), stages, out, raw, config, bvh, resident);
}

}  // namespace

DevicePlocTree build_ploc_tree_on_device(std::span<const Triangle> triangles, int radius, DeviceBuildStages* stages,
                                         int device) {
    DeviceBuildStages local;
    DevicePlocTree tree;
    build_raw(triangles, radius, stages ? *stages : local, device, tree, true);
    return tree;
}

Bvh build_ploc_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                         const PlocOptions& ploc_options, DeviceBuildStages* stages, int device,
                         DeviceBvh* resident) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    DevicePlocTree tree;
    Bvh bvh;
    if (build_raw(triangles, ploc_options.radius, s, device, tree, false, &config, &bvh, resident)) {
        s.emitted_on_device = true;
        return bvh;
    }
    const auto start = std::chrono::steady_clock::now();
    bvh = emit_ploc_tree(triangles, config, std::move(tree.order), tree.children, tree.iteration_nodes);
    s.emit_ms = elapsed_ms(start);
    return bvh;
}

}  // namespace rf::cuda
