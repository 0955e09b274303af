// GridBvh and GridBvhSplit on the device (Garanzha 2014, dissertation ch. 4),
// building rf::build_grid_bvh's tree through the shared steps of
// src/accel/bvh/builders/grid_bvh_steps.h:
//  1. references (§4.4): one thread per triangle writes its reference; the
//     scene box is a cub::DeviceReduce of the reference boxes (min/max are
//     exact and skip NaN as the CPU's fold does, so any order gives the
//     CPU's box). GridBvhSplit: two passes,
//     each one thread per reference for its split request, a CUB inclusive
//     scan of the requests (the total asked), one thread per reference for
//     its share of the free slots (the CPU's rounding-down rule, so exactly
//     the same references are split when the budget runs out), a CUB scan of
//     the output slots, one thread per reference writing its parts, and
//     cub::DeviceSelect::If dropping the empty parts in order.
//  2. 30-bit Grid0 keys of the reference centres, sorted ONCE with the
//     reference ids by a stable cub::DeviceRadixSort (§4.2 steps 1-3).
//  3. Grid0 by compaction (§4.2 steps 4-5): flags where the 21-bit top key
//     and the 30-bit key change, CUB inclusive scans giving each sorted
//     position its top-cell and Grid0-cell rank, one thread per position
//     scattering the first positions, the top keys and the bottom-grid
//     occupancy bits (atomicOr), then TopGrid0 (128^3 ranks) by scatter.
//  4. count-only levels (§4.2 step 6): Grid4 by atomicAdd from the top cells,
//     Grid5..Grid7 one thread per cell summing its 8 children.
//  5. EmitHierarchy by task queues (§4.3, Algorithm 4.1), one launch per tree
//     level: 8 threads per task (4 tasks per warp, one atomicAdd per warp to
//     dequeue), the task's cells visited by its 8 threads into shared-memory
//     bins with integer atomics (so the bins are the CPU's in any order),
//     then process_task's refinement and 8-bin SAH over 7 planes per axis on
//     each thread alike; children and leaves are written at warp-local
//     prefix sums (ballot + popc) after ONE packed atomicAdd per warp.
//     Children of a level are numbered in dequeue order: the emission does
//     not depend on the numbering, so the BVH is the CPU's.
//  6. leaf gathering (the reference shuffling of §4.3): one thread per
//     reference descends the hierarchy with its Grid0 cell
//     (leaf_of_reference), one stable cub::DeviceRadixSort of (leaf,
//     reference), one thread per sorted position writing the leaf ranges.
//  7. leaf finishing (grid_bvh_finish_steps.h): one thread per leaf sorts
//     its reference ids, gathers the references into local arrays, merges
//     the parts of one triangle, and keeps them as one leaf or splits them
//     (leaves over max_leaf_size, or where the SAH says so) by the binned
//     SAH with an explicit stack, into per-leaf slots at its reference range
//     (2 nodes and 1 triangle per reference, so no scan is needed).
//  8. canonical emission, one thread per hierarchy node and one launch per
//     tree level (levelOffset of Algorithm 4.1): subtree sizes and boxes
//     bottom-up, positions top-down, then one copy kernel writing the
//     BvhNodes and triangle indices; only the BVH is downloaded.
// A leaf of more than kDeviceFinishRefs references (a crowded Grid0 cell or
// the depth limit) does not fit one thread: then 7-8 run on the host, the
// CPU builder's own code (emit_grid_bvh_hierarchy) on the downloaded
// references, hierarchy and leaf groups (stages.emitted_on_device = false).
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>
#include <string>
#include <utility>
#include <vector>

#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/grid_bvh_emit.h"
#include "accel/bvh/builders/grid_bvh_finish_steps.h"
#include "accel/bvh/builders/grid_bvh_steps.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/morton_sort.h"
#include "backend/backends.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using gridbvh::CellBox;
using gridbvh::EmitPosition;
using gridbvh::FinishOptions;
using gridbvh::LeafSummary;
using gridbvh::SubtreeSize;
using gridbvh::GridFrame;
using gridbvh::GridRef;
using gridbvh::NodeRegion;
using gridbvh::SparseGridView;
using gridbvh::SplitTask;
using gridbvh::TaskBins;
using gridbvh::TaskOutcome;

constexpr int kBlockSize = 256;   // a multiple of 32: every warp is full, so full-mask ballots are valid
constexpr int kTaskThreads = 8;   // threads per split task (one per bin of an axis)
constexpr int kTasksPerWarp = 32 / kTaskThreads;
constexpr int kTasksPerBlock = kBlockSize / kTaskThreads;
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kMaxQueueBlocks = 4096;  // warps loop over the queue beyond this
constexpr uint32_t kTopCells = uint32_t(gridbvh::kTopRes) * gridbvh::kTopRes * gridbvh::kTopRes;

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

template <class T>
T download_value(const T* device_value) {
    T value{};
    RF_CUDA_CHECK(cudaMemcpy(&value, device_value, sizeof value, cudaMemcpyDeviceToHost));
    return value;
}

// CUB's temporary storage, counted by the meter; released on return.
class CubTemp {
public:
    CubTemp(MemoryMeter& meter, const char* name) : meter_(meter), buffer_(name) {}
    ~CubTemp() { meter_.release(buffer_); }
    void* get(size_t bytes) {
        if (buffer_.bytes() < bytes || buffer_.data() == nullptr) meter_.allocate(buffer_, bytes > 0 ? bytes : 1);
        return buffer_.data();
    }

private:
    MemoryMeter& meter_;
    DeviceBuffer<uint8_t> buffer_;
};

// The CPU folds into an accumulator that starts at +-FLT_MAX, so a NaN
// coordinate never wins there; CUB combines in tree order, so NaN must lose
// from either side here to give the CPU's box.
__device__ float min_skipping_nan(float a, float b) { return isnan(b) ? a : isnan(a) ? b : (b < a ? b : a); }
__device__ float max_skipping_nan(float a, float b) { return isnan(b) ? a : isnan(a) ? b : (b > a ? b : a); }

struct BoxUnion {
    __device__ Box3f operator()(const Box3f& a, const Box3f& b) const {
        return {{min_skipping_nan(a.lo.x, b.lo.x), min_skipping_nan(a.lo.y, b.lo.y), min_skipping_nan(a.lo.z, b.lo.z)},
                {max_skipping_nan(a.hi.x, b.hi.x), max_skipping_nan(a.hi.y, b.hi.y), max_skipping_nan(a.hi.z, b.hi.z)}};
    }
};

struct ValidRef {
    __device__ bool operator()(const GridRef& r) const { return r.prim != gridbvh::kInvalidRef; }
};

// ---- 1. references and partial triangles ----

__global__ void triangle_refs_kernel(const Triangle* triangles, uint32_t n, GridRef* refs, Box3f* boxes) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    refs[i] = gridbvh::triangle_ref(triangles[i], i);
    boxes[i] = refs[i].bounds();
}

__global__ void split_request_kernel(const GridRef* refs, uint32_t n, float max_width, uint64_t* requests) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n) requests[i] = gridbvh::split_request(refs[i], max_width);
}

// Output slots of each reference: its share of the free slots, plus itself.
__global__ void split_slots_kernel(const uint64_t* requests, uint32_t n, uint64_t asked, uint64_t available,
                                   uint64_t* slots) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n) slots[i] = uint64_t{gridbvh::split_share(uint32_t(requests[i]), asked, available)} + 1;
}

// One thread per reference: its parts at its slot range (slot_ends: inclusive scan).
__global__ void write_parts_kernel(const Triangle* triangles, const GridRef* refs, const uint64_t* requests,
                                   const uint64_t* slot_ends, uint32_t n, uint64_t asked, uint64_t available,
                                   GridFrame frame, GridRef* parts) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    const uint32_t splits = gridbvh::split_share(uint32_t(requests[i]), asked, available);
    GridRef* out = parts + (slot_ends[i] - splits - 1);
    if (splits == 0) {
        *out = refs[i];
    } else {
        gridbvh::write_parts(triangles[refs[i].prim], refs[i], splits, frame, out);
    }
}

// ---- 2. keys ----

__global__ void cell_keys_kernel(const GridRef* refs, uint32_t n, GridFrame frame, uint32_t* keys, uint32_t* ids) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    keys[i] = gridbvh::fine_key(frame, refs[i].centroid());
    ids[i] = i;
}

// ---- 3. Grid0 by compaction ----

__global__ void cell_start_flags_kernel(const uint32_t* keys, uint32_t n, uint32_t* top_flags, uint32_t* fine_flags) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    top_flags[i] = i == 0 || (keys[i] >> 9) != (keys[i - 1] >> 9);
    fine_flags[i] = i == 0 || keys[i] != keys[i - 1];
}

// top_rank / fine_rank: inclusive scans of the flags (rank + 1 at each position).
__global__ void grid0_scatter_kernel(const uint32_t* keys, uint32_t n, const uint32_t* top_rank,
                                     const uint32_t* fine_rank, uint32_t occupied, uint32_t cells, uint32_t* top_key,
                                     uint32_t* top_begin, uint32_t* top_cells, unsigned long long* top_mask,
                                     uint32_t* fine_begin) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i == 0) {
        top_begin[occupied] = n;
        top_cells[occupied] = cells;
        fine_begin[cells] = n;
    }
    if (i >= n) return;
    const bool new_cell = i == 0 || fine_rank[i] != fine_rank[i - 1];
    if (!new_cell) return;
    const uint32_t m = top_rank[i] - 1, c = fine_rank[i] - 1;
    fine_begin[c] = i;
    const uint32_t sub = keys[i] & uint32_t(gridbvh::kSubCells - 1);
    atomicOr(&top_mask[size_t{m} * gridbvh::kMaskWords + sub / 64], 1ull << (sub % 64));
    if (i == 0 || top_rank[i] != top_rank[i - 1]) {
        top_begin[m] = i;
        top_key[m] = keys[i] >> 9;
        top_cells[m] = c;
    }
}

__global__ void top_index_kernel(const uint32_t* top_key, uint32_t occupied, uint32_t* top_index) {
    const uint32_t m = blockIdx.x * kBlockSize + threadIdx.x;
    if (m < occupied) top_index[top_key[m]] = m;
}

// ---- 4. count-only levels ----

__global__ void grid4_kernel(const uint32_t* top_key, const uint32_t* top_begin, uint32_t occupied, uint32_t* grid4) {
    const uint32_t m = blockIdx.x * kBlockSize + threadIdx.x;
    if (m >= occupied) return;
    constexpr uint32_t kTop = gridbvh::kTopRes, kRes = kTop / 2;
    const uint32_t key = top_key[m];
    const uint32_t x = key % kTop, y = (key / kTop) % kTop, z = key / (kTop * kTop);
    atomicAdd(&grid4[(x >> 1) + kRes * ((y >> 1) + kRes * (z >> 1))], top_begin[m + 1] - top_begin[m]);
}

__global__ void coarser_level_kernel(const uint32_t* child, uint32_t res, uint32_t* parent) {
    const uint32_t c = blockIdx.x * kBlockSize + threadIdx.x;
    if (c >= res * res * res) return;
    const uint32_t child_res = 2 * res;
    const uint32_t x = c % res, y = (c / res) % res, z = c / (res * res);
    uint32_t sum = 0;
    for (uint32_t d = 0; d < 8; ++d) {
        const uint32_t cx = 2 * x + (d & 1), cy = 2 * y + ((d >> 1) & 1), cz = 2 * z + (d >> 2);
        sum += child[cx + child_res * (cy + child_res * cz)];
    }
    parent[c] = sum;
}

// ---- 5. EmitHierarchy by task queues ----

// A task's bins while its 8 threads fill them (integer atomics: any order
// gives the same bins).
struct SharedBins {
    uint32_t count[3][gridbvh::kMaxUseRes];
    int lo[3][gridbvh::kMaxUseRes][3];
    int hi[3][gridbvh::kMaxUseRes][3];
};

struct LevelOutput {
    SplitTask* next;          // the next level's tasks, two per split
    uint32_t* hnodes;         // per node: left child or kLeafBit | leaf
    NodeRegion* regions;      // per node: its IBB at creation
    SplitTask* leaves;        // per leaf: its refined task
    uint32_t next_level_base; // first node of the next level
    uint32_t leaf_base;       // leaves made by the earlier levels
};

// counters[0]: dequeue head; counters[1]: (leaves << 32) | splits of this level.
__global__ void split_level_kernel(SparseGridView grid, GridFrame frame, const SplitTask* input, uint32_t count,
                                   uint32_t leaf_size, LevelOutput out, unsigned long long* counters) {
    __shared__ SharedBins shared_bins[kTasksPerBlock];
    const uint32_t lane = threadIdx.x % 32;
    const uint32_t group = lane / kTaskThreads, sub = lane % kTaskThreads;
    const uint32_t group_mask = 0xffu << (group * kTaskThreads);
    SharedBins& sb = shared_bins[threadIdx.x / kTaskThreads];
    for (;;) {
        unsigned long long base = 0;
        if (lane == 0) base = atomicAdd(&counters[0], static_cast<unsigned long long>(kTasksPerWarp));  // one per warp
        base = __shfl_sync(kFullMask, base, 0);
        if (base >= count) return;  // uniform over the warp
        const uint64_t at = base + group;
        const bool has = at < count;
        TaskOutcome outcome{};
        if (has) {
            // The task's 8 threads visit its cells into the shared bins; each then takes a copy.
            auto scan = [&](int level, const CellBox& box, TaskBins& bins) {
                for (int k = int(sub); k < 3 * gridbvh::kMaxUseRes; k += kTaskThreads) {
                    const int a = k / gridbvh::kMaxUseRes, b = k % gridbvh::kMaxUseRes;
                    sb.count[a][b] = 0;
                    for (int c = 0; c < 3; ++c) {
                        sb.lo[a][b][c] = 1 << 20;
                        sb.hi[a][b][c] = -1;
                    }
                }
                __syncwarp(group_mask);
                gridbvh::for_each_cell(
                    grid, level, box,
                    [&](int x, int y, int z, uint32_t n) {
                        const int p[3] = {x, y, z};
                        for (int a = 0; a < 3; ++a) {
                            const int b = p[a] - box.lo[a];
                            atomicAdd(&sb.count[a][b], n);
                            for (int c = 0; c < 3; ++c) {
                                atomicMin(&sb.lo[a][b][c], p[c]);
                                atomicMax(&sb.hi[a][b][c], p[c]);
                            }
                        }
                    },
                    int(sub), kTaskThreads);
                __syncwarp(group_mask);
                for (int a = 0; a < 3; ++a) {
                    for (int b = 0; b < gridbvh::kMaxUseRes; ++b) {
                        bins.bins[a][b].count = sb.count[a][b];
                        for (int c = 0; c < 3; ++c) {
                            bins.bins[a][b].lo[c] = sb.lo[a][b][c];
                            bins.bins[a][b].hi[c] = sb.hi[a][b][c];
                        }
                    }
                }
                __syncwarp(group_mask);  // every copy is taken before the next clear
            };
            outcome = gridbvh::process_task(input[at], leaf_size, frame, scan);
        }
        const bool leader = has && sub == 0;
        const uint32_t splits = __ballot_sync(kFullMask, leader && outcome.split);
        const uint32_t leaves = __ballot_sync(kFullMask, leader && !outcome.split);
        unsigned long long packed = 0;
        if (lane == 0 && (splits | leaves) != 0) {  // one enqueue per warp
            packed = atomicAdd(&counters[1], (static_cast<unsigned long long>(__popc(leaves)) << 32) | __popc(splits));
        }
        packed = __shfl_sync(kFullMask, packed, 0);
        if (!leader) continue;
        const uint32_t below = (1u << lane) - 1;
        const uint32_t node = outcome.left.node;
        if (outcome.split) {
            const uint32_t slot = uint32_t(packed & 0xffffffffu) + __popc(splits & below);
            const uint32_t pair = out.next_level_base + 2 * slot;
            out.hnodes[node] = pair;
            SplitTask left = outcome.left, right = outcome.right;
            left.node = pair;
            right.node = pair + 1;
            out.regions[pair] = NodeRegion{left.box, left.level};
            out.regions[pair + 1] = NodeRegion{right.box, right.level};
            out.next[2 * slot] = left;
            out.next[2 * slot + 1] = right;
        } else {
            const uint32_t leaf = out.leaf_base + uint32_t(packed >> 32) + __popc(leaves & below);
            out.hnodes[node] = gridbvh::kLeafBit | leaf;
            out.leaves[leaf] = outcome.left;
        }
    }
}

// ---- 6. leaf gathering ----

// One thread per reference: its leaf by descent (leaf_of_reference), with its id for the sort.
__global__ void leaf_of_kernel(const uint32_t* hnodes, const NodeRegion* regions, GridFrame frame, const GridRef* refs,
                               uint32_t n, uint32_t* leaf_of, uint32_t* ids) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    leaf_of[i] = gridbvh::leaf_of_reference(hnodes, regions, frame, refs[i]);
    ids[i] = i;
}

// One thread per sorted position: the first position of every leaf that
// starts here (leaves without references start where the next one does).
__global__ void leaf_begin_kernel(const uint32_t* sorted_leaf, uint32_t n, uint32_t leaf_count, uint32_t* leaf_begin) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    if (i == 0 || sorted_leaf[i] != sorted_leaf[i - 1]) {
        for (uint32_t l = i == 0 ? 0 : sorted_leaf[i - 1] + 1; l <= sorted_leaf[i]; ++l) leaf_begin[l] = i;
    }
    if (i == n - 1) {
        for (uint32_t l = sorted_leaf[i] + 1; l <= leaf_count; ++l) leaf_begin[l] = n;
    }
}

// ---- 7. leaf finishing ----

// One thread per leaf: raises the flag when the leaf has more references
// than one thread can finish.
__global__ void oversized_leaf_kernel(const uint32_t* leaf_begin, uint32_t leaf_count, uint32_t* oversized) {
    const uint32_t l = blockIdx.x * kBlockSize + threadIdx.x;
    if (l < leaf_count && leaf_begin[l + 1] - leaf_begin[l] > gridbvh::kDeviceFinishRefs) *oversized = 1;
}

// One thread per leaf: the shared finishing into the leaf's slots, nodes at
// 2 leaf_begin[l] (room for 2 count - 1) and triangles at leaf_begin[l].
__global__ void finish_leaves_kernel(const GridRef* refs, const uint32_t* leaf_refs, const uint32_t* leaf_begin,
                                     const SplitTask* leaves, uint32_t leaf_count, FinishOptions options,
                                     LeafSummary* summaries, BvhNode* leaf_nodes, uint32_t* leaf_prims) {
    const uint32_t l = blockIdx.x * kBlockSize + threadIdx.x;
    if (l >= leaf_count) return;
    const uint32_t begin = leaf_begin[l];
    summaries[l] = gridbvh::finish_small_leaf(refs, leaf_refs + begin, leaf_begin[l + 1] - begin, leaves[l].depth,
                                              options, leaf_nodes + 2 * size_t{begin}, leaf_prims + begin);
}

// ---- 8. canonical emission ----

// Hierarchy nodes [first, end) of one level: sizes and boxes from the level below.
__global__ void emit_sizes_kernel(const uint32_t* hnodes, const LeafSummary* summaries, uint32_t first, uint32_t end,
                                  SubtreeSize* sizes, Box3f* boxes) {
    const uint32_t h = first + blockIdx.x * kBlockSize + threadIdx.x;
    if (h < end) gridbvh::emit_size_and_box(h, hnodes, summaries, sizes, boxes);
}

// Hierarchy nodes [first, end) of one level place their children.
__global__ void emit_positions_kernel(const uint32_t* hnodes, const SubtreeSize* sizes, uint32_t first, uint32_t end,
                                      EmitPosition* at) {
    const uint32_t h = first + blockIdx.x * kBlockSize + threadIdx.x;
    if (h < end) gridbvh::emit_positions(h, hnodes, sizes, at);
}

// One thread per hierarchy node: its BvhNode, or its leaf's nodes and triangles.
__global__ void emit_copy_kernel(const uint32_t* hnodes, uint32_t node_count, const Box3f* boxes, const EmitPosition* at,
                                 const LeafSummary* summaries, const uint32_t* leaf_begin, const BvhNode* leaf_nodes,
                                 const uint32_t* leaf_prims, BvhNode* out_nodes, uint32_t* out_prims) {
    const uint32_t h = blockIdx.x * kBlockSize + threadIdx.x;
    if (h >= node_count) return;
    const uint32_t first = hnodes[h];
    if (!(first & gridbvh::kLeafBit)) {
        gridbvh::emit_inner_node(boxes[h], at[h], out_nodes);
        return;
    }
    const uint32_t leaf = first & ~gridbvh::kLeafBit;
    const uint32_t begin = leaf_begin[leaf];
    gridbvh::emit_leaf(summaries[leaf], leaf_nodes + 2 * size_t{begin}, leaf_prims + begin, at[h], out_nodes,
                       out_prims);
}

// The device pipeline for n >= 1 triangles: returns true with the BVH in
// `bvh` when the device emitted it, false with `hierarchy` filled for the
// host emission when a leaf was too large for one thread.
bool build_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                     bool partial_triangles, DeviceBuildStages& stages, GridHierarchy& hierarchy, Bvh& bvh) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    const uint32_t leaf_size = static_cast<uint32_t>(std::max(1, config.max_leaf_size));
    MemoryMeter meter;
    EventTimer timer;
    CubTemp temp(meter, "GridBvh: CUB temporary storage");
    size_t temp_bytes = 0;

    DeviceBuffer<Triangle> device_triangles("GridBvh: triangles");
    meter.allocate(device_triangles, n);
    timer.start();
    device_triangles.upload(triangles);
    stages.upload_ms = timer.stop_ms();

    // 1. References, the scene box, partial triangles.
    DeviceBuffer<GridRef> refs("GridBvh: references");
    DeviceBuffer<Box3f> boxes("GridBvh: reference boxes"), scene_box("GridBvh: scene box");
    meter.allocate(refs, n);
    meter.allocate(boxes, n);
    meter.allocate(scene_box, 1);
    timer.start();
    triangle_refs_kernel<<<blocks_for(n), kBlockSize>>>(device_triangles.data(), n, refs.data(), boxes.data());
    RF_CUDA_CHECK(cub::DeviceReduce::Reduce(nullptr, temp_bytes, boxes.data(), scene_box.data(), n, BoxUnion{}, Box3f{}));
    RF_CUDA_CHECK(cub::DeviceReduce::Reduce(temp.get(temp_bytes), temp_bytes, boxes.data(), scene_box.data(), n,
                                            BoxUnion{}, Box3f{}));
    const GridFrame frame(download_value(scene_box.data()));
    meter.release(boxes);
    meter.release(scene_box);
    uint32_t ref_count = n;
    const float scene_extent = std::max(frame.extent.x, std::max(frame.extent.y, frame.extent.z));
    const float max_width = scene_extent / 128.0f;  // formula 4.1, sceneDividePortion = 1/128
    const float budget = grid_bvh.split_budget;
    if (partial_triangles && max_width > 0.0f && budget > 0.0f) {
        const uint64_t budget_slots = uint64_t(std::floor(double(budget) * double(n)));
        uint64_t used = 0;
        for (int pass = 0; pass < 2 && used < budget_slots; ++pass) {
            const uint64_t available = budget_slots - used;
            DeviceBuffer<uint64_t> requests("GridBvhSplit: split requests"), ends("GridBvhSplit: slot ends");
            meter.allocate(requests, ref_count);
            meter.allocate(ends, ref_count);
            split_request_kernel<<<blocks_for(ref_count), kBlockSize>>>(refs.data(), ref_count, max_width,
                                                                        requests.data());
            RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, requests.data(), ends.data(), ref_count));
            RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.get(temp_bytes), temp_bytes, requests.data(), ends.data(),
                                                        ref_count));
            const uint64_t asked = download_value(ends.data() + ref_count - 1);
            if (asked == 0) break;  // nothing wider than the limit: later passes ask nothing either
            split_slots_kernel<<<blocks_for(ref_count), kBlockSize>>>(requests.data(), ref_count, asked, available,
                                                                      ends.data());
            RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, ends.data(), ends.data(), ref_count));
            RF_CUDA_CHECK(
                cub::DeviceScan::InclusiveSum(temp.get(temp_bytes), temp_bytes, ends.data(), ends.data(), ref_count));
            const uint64_t slots = download_value(ends.data() + ref_count - 1);
            // Node and leaf links keep their top bit as the leaf flag (kLeafBit).
            if (slots >= (uint64_t{1} << 30)) throw Error("GridBvhSplit device build: more than 2^30 parts");
            DeviceBuffer<GridRef> parts("GridBvhSplit: partial triangles");
            DeviceBuffer<uint32_t> kept("GridBvhSplit: kept parts");
            meter.allocate(parts, slots);
            meter.allocate(kept, 1);
            write_parts_kernel<<<blocks_for(ref_count), kBlockSize>>>(device_triangles.data(), refs.data(),
                                                                      requests.data(), ends.data(), ref_count, asked,
                                                                      available, frame, parts.data());
            meter.release(requests);
            meter.release(ends);
            meter.release(refs);
            meter.allocate(refs, slots);
            RF_CUDA_CHECK(cub::DeviceSelect::If(nullptr, temp_bytes, parts.data(), refs.data(), kept.data(),
                                                static_cast<int64_t>(slots), ValidRef{}));
            RF_CUDA_CHECK(cub::DeviceSelect::If(temp.get(temp_bytes), temp_bytes, parts.data(), refs.data(),
                                                kept.data(), static_cast<int64_t>(slots), ValidRef{}));
            const uint32_t next_count = download_value(kept.data());
            meter.release(parts);
            meter.release(kept);
            used += next_count - ref_count;
            ref_count = next_count;
        }
    }
    stages.partial_triangles_ms = timer.stop_ms();
    stages.references = ref_count;

    // 2. Keys, sorted once.
    DeviceBuffer<uint32_t> keys[2] = {DeviceBuffer<uint32_t>("GridBvh: cell keys"),
                                      DeviceBuffer<uint32_t>("GridBvh: sorted cell keys")};
    DeviceBuffer<uint32_t> ids[2] = {DeviceBuffer<uint32_t>("GridBvh: reference ids"),
                                     DeviceBuffer<uint32_t>("GridBvh: sorted references")};
    for (int b = 0; b < 2; ++b) {
        meter.allocate(keys[b], ref_count);
        meter.allocate(ids[b], ref_count);
    }
    timer.start();
    cell_keys_kernel<<<blocks_for(ref_count), kBlockSize>>>(refs.data(), ref_count, frame, keys[0].data(),
                                                            ids[0].data());
    cub::DoubleBuffer<uint32_t> key_buffers(keys[0].data(), keys[1].data()), id_buffers(ids[0].data(), ids[1].data());
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, key_buffers, id_buffers, ref_count, 0, 30));
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.get(temp_bytes), temp_bytes, key_buffers, id_buffers, ref_count,
                                                  0, 30));
    stages.sort_ms = timer.stop_ms();
    const int sorted = key_buffers.Current() == keys[0].data() ? 0 : 1;
    meter.release(keys[1 - sorted]);
    meter.release(ids[1 - sorted]);
    const uint32_t* sorted_keys = keys[sorted].data();

    // 3. Grid0: top cells and bottom grids by compaction.
    DeviceBuffer<uint32_t> top_rank("GridBvh: top cell ranks"), fine_rank("GridBvh: Grid0 cell ranks");
    meter.allocate(top_rank, ref_count);
    meter.allocate(fine_rank, ref_count);
    timer.start();
    {
        DeviceBuffer<uint32_t> top_flags("GridBvh: top cell starts"), fine_flags("GridBvh: Grid0 cell starts");
        meter.allocate(top_flags, ref_count);
        meter.allocate(fine_flags, ref_count);
        cell_start_flags_kernel<<<blocks_for(ref_count), kBlockSize>>>(sorted_keys, ref_count, top_flags.data(),
                                                                       fine_flags.data());
        RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, top_flags.data(), top_rank.data(), ref_count));
        RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.get(temp_bytes), temp_bytes, top_flags.data(), top_rank.data(),
                                                    ref_count));
        RF_CUDA_CHECK(cub::DeviceScan::InclusiveSum(temp.get(temp_bytes), temp_bytes, fine_flags.data(),
                                                    fine_rank.data(), ref_count));
        meter.release(top_flags);
        meter.release(fine_flags);
    }
    const uint32_t occupied = download_value(top_rank.data() + ref_count - 1);
    const uint32_t cells = download_value(fine_rank.data() + ref_count - 1);
    DeviceBuffer<uint32_t> top_index("GridBvh: TopGrid0"), top_key("GridBvh: top cell keys"),
        top_begin("GridBvh: top cell starts"), top_cells("GridBvh: top cell first Grid0 cells"),
        fine_begin("GridBvh: Grid0 cell starts");
    DeviceBuffer<unsigned long long> top_mask("GridBvh: bottom grid occupancy");
    meter.allocate(top_index, kTopCells);
    meter.allocate(top_key, occupied);
    meter.allocate(top_begin, size_t{occupied} + 1);
    meter.allocate(top_cells, size_t{occupied} + 1);
    meter.allocate(top_mask, size_t{occupied} * gridbvh::kMaskWords);
    meter.allocate(fine_begin, size_t{cells} + 1);
    RF_CUDA_CHECK(cudaMemsetAsync(top_mask.data(), 0, top_mask.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(top_index.data(), 0xff, top_index.bytes()));  // kEmptyCell
    grid0_scatter_kernel<<<blocks_for(ref_count), kBlockSize>>>(sorted_keys, ref_count, top_rank.data(),
                                                                fine_rank.data(), occupied, cells, top_key.data(),
                                                                top_begin.data(), top_cells.data(), top_mask.data(),
                                                                fine_begin.data());
    top_index_kernel<<<blocks_for(occupied), kBlockSize>>>(top_key.data(), occupied, top_index.data());
    stages.grid0_ms = timer.stop_ms();
    stages.occupied_top_cells = occupied;
    meter.release(top_rank);
    meter.release(fine_rank);
    meter.release(keys[sorted]);
    meter.release(ids[sorted]);  // the hierarchy reads counts only; the leaves find their references by descent

    // 4. Count-only levels Grid4..Grid7.
    DeviceBuffer<uint32_t> dense[4] = {DeviceBuffer<uint32_t>("GridBvh: Grid4"), DeviceBuffer<uint32_t>("GridBvh: Grid5"),
                                       DeviceBuffer<uint32_t>("GridBvh: Grid6"), DeviceBuffer<uint32_t>("GridBvh: Grid7")};
    for (int k = 0; k < 4; ++k) {
        const size_t res = size_t(gridbvh::kFineRes) >> (4 + k);
        meter.allocate(dense[k], res * res * res);
    }
    timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(dense[0].data(), 0, dense[0].bytes()));
    grid4_kernel<<<blocks_for(occupied), kBlockSize>>>(top_key.data(), top_begin.data(), occupied, dense[0].data());
    for (int k = 1; k < 4; ++k) {
        const uint32_t res = uint32_t(gridbvh::kFineRes) >> (4 + k);
        coarser_level_kernel<<<blocks_for(size_t{res} * res * res), kBlockSize>>>(dense[k - 1].data(), res,
                                                                                   dense[k].data());
    }
    stages.coarse_levels_ms = timer.stop_ms();
    const SparseGridView view{top_index.data(), top_begin.data(), top_cells.data(),
                              reinterpret_cast<const uint64_t*>(top_mask.data()), fine_begin.data(),
                              {dense[0].data(), dense[1].data(), dense[2].data(), dense[3].data()}};

    // 5. EmitHierarchy: one launch per tree level. A level holds at most
    // ref_count tasks (disjoint, none empty), the tree 2 ref_count - 1 nodes.
    const size_t max_nodes = 2 * size_t{ref_count} - 1;
    DeviceBuffer<SplitTask> queue[2] = {DeviceBuffer<SplitTask>("GridBvh: task queue A"),
                                        DeviceBuffer<SplitTask>("GridBvh: task queue B")};
    DeviceBuffer<uint32_t> hnodes("GridBvh: hierarchy nodes");
    DeviceBuffer<NodeRegion> regions("GridBvh: hierarchy node regions");
    DeviceBuffer<SplitTask> leaves("GridBvh: hierarchy leaves");
    DeviceBuffer<unsigned long long> counters("GridBvh: queue counters");
    meter.allocate(queue[0], ref_count);
    meter.allocate(queue[1], ref_count);
    meter.allocate(hnodes, max_nodes);
    meter.allocate(regions, max_nodes);
    meter.allocate(leaves, ref_count);
    meter.allocate(counters, 2);
    const SplitTask root = gridbvh::root_task(ref_count);
    const NodeRegion root_region{root.box, root.level};
    RF_CUDA_CHECK(cudaMemcpy(queue[0].data(), &root, sizeof root, cudaMemcpyHostToDevice));
    RF_CUDA_CHECK(cudaMemcpy(regions.data(), &root_region, sizeof root_region, cudaMemcpyHostToDevice));
    std::vector<uint32_t> level_offset{0};
    uint32_t count = 1, leaf_count = 0;
    int in = 0;
    timer.start();
    while (count != 0) {
        const uint32_t next_base = level_offset.back() + count;
        level_offset.push_back(next_base);
        RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
        const LevelOutput out{queue[1 - in].data(), hnodes.data(), regions.data(), leaves.data(), next_base, leaf_count};
        const uint32_t blocks = std::min<uint32_t>((count + kTasksPerBlock - 1) / kTasksPerBlock, kMaxQueueBlocks);
        split_level_kernel<<<blocks, kBlockSize>>>(view, frame, queue[in].data(), count, leaf_size, out,
                                                   counters.data());
        RF_CUDA_CHECK(cudaGetLastError());
        const unsigned long long made = download_value(counters.data() + 1);  // waits for the level
        const uint32_t splits = uint32_t(made & 0xffffffffu), new_leaves = uint32_t(made >> 32);
        leaf_count += new_leaves;
        count = 2 * splits;
        if (count > ref_count || next_base + size_t{count} > max_nodes || leaf_count > ref_count) {
            throw Error("GridBvh device build: task queue overflow");
        }
        in = 1 - in;
    }
    stages.hierarchy_ms = timer.stop_ms();
    meter.release(queue[0]);
    meter.release(queue[1]);
    meter.release(counters);
    for (DeviceBuffer<uint32_t>& level : dense) meter.release(level);
    meter.release(top_index);
    meter.release(top_key);
    meter.release(top_begin);
    meter.release(top_cells);
    meter.release(top_mask);
    meter.release(fine_begin);

    // 6. Leaf gathering: each reference's leaf, one stable sort of (leaf,
    // reference) pairs (ascending references within a leaf, as the CPU
    // orders them), the leaf ranges.
    DeviceBuffer<uint32_t> leaf_of[2] = {DeviceBuffer<uint32_t>("GridBvh: leaf of reference"),
                                         DeviceBuffer<uint32_t>("GridBvh: sorted leaves")};
    DeviceBuffer<uint32_t> leaf_ids[2] = {DeviceBuffer<uint32_t>("GridBvh: leaf reference ids"),
                                          DeviceBuffer<uint32_t>("GridBvh: leaf references")};
    DeviceBuffer<uint32_t> leaf_begin("GridBvh: leaf ranges");
    for (int b = 0; b < 2; ++b) {
        meter.allocate(leaf_of[b], ref_count);
        meter.allocate(leaf_ids[b], ref_count);
    }
    meter.allocate(leaf_begin, size_t{leaf_count} + 1);
    int leaf_bits = 1;
    while (leaf_bits < 32 && (leaf_count >> leaf_bits) != 0) ++leaf_bits;
    timer.start();
    leaf_of_kernel<<<blocks_for(ref_count), kBlockSize>>>(hnodes.data(), regions.data(), frame, refs.data(), ref_count,
                                                          leaf_of[0].data(), leaf_ids[0].data());
    cub::DoubleBuffer<uint32_t> leaf_keys(leaf_of[0].data(), leaf_of[1].data()),
        leaf_values(leaf_ids[0].data(), leaf_ids[1].data());
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, leaf_keys, leaf_values, ref_count, 0, leaf_bits));
    RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp.get(temp_bytes), temp_bytes, leaf_keys, leaf_values, ref_count, 0,
                                                  leaf_bits));
    leaf_begin_kernel<<<blocks_for(ref_count), kBlockSize>>>(leaf_keys.Current(), ref_count, leaf_count,
                                                             leaf_begin.data());
    meter.release(leaf_of[0]);
    meter.release(leaf_of[1]);
    const int grouped = leaf_values.Current() == leaf_ids[0].data() ? 0 : 1;
    meter.release(leaf_ids[1 - grouped]);
    DeviceBuffer<uint32_t> oversized("GridBvh: oversized leaf flag");
    meter.allocate(oversized, 1);
    RF_CUDA_CHECK(cudaMemsetAsync(oversized.data(), 0, oversized.bytes()));
    oversized_leaf_kernel<<<blocks_for(leaf_count), kBlockSize>>>(leaf_begin.data(), leaf_count, oversized.data());
    const bool fits = download_value(oversized.data()) == 0;
    meter.release(oversized);
    const uint32_t nodes = level_offset.back();

    if (!fits) {
        // A leaf too large for one thread: the host finishes and emits.
        stages.leaf_finish_ms = timer.stop_ms();  // the host's finishing is added later
        stages.peak_device_bytes = meter.peak();
        timer.start();
        hierarchy.frame = frame;
        hierarchy.refs = download_all(refs, ref_count);
        hierarchy.hnodes = download_all(hnodes, nodes);
        hierarchy.regions = download_all(regions, nodes);
        hierarchy.leaves = download_all(leaves, leaf_count);
        hierarchy.level_offset = std::move(level_offset);
        hierarchy.leaf_refs = download_all(leaf_ids[grouped], ref_count);
        hierarchy.leaf_begin = download_all(leaf_begin, size_t{leaf_count} + 1);
        stages.download_ms = timer.stop_ms();
        return false;
    }

    // 7. Leaf finishing: per-leaf slots at the leaf's reference range.
    meter.release(regions);
    DeviceBuffer<LeafSummary> summaries("GridBvh: finished leaves");
    DeviceBuffer<BvhNode> leaf_nodes("GridBvh: leaf subtrees");
    DeviceBuffer<uint32_t> leaf_prims("GridBvh: leaf triangles");
    meter.allocate(summaries, leaf_count);
    meter.allocate(leaf_nodes, 2 * size_t{ref_count});
    meter.allocate(leaf_prims, ref_count);
    const FinishOptions finish{leaf_size, config.sah.traversal, config.sah.intersection};
    finish_leaves_kernel<<<blocks_for(leaf_count), kBlockSize>>>(refs.data(), leaf_ids[grouped].data(),
                                                                 leaf_begin.data(), leaves.data(), leaf_count, finish,
                                                                 summaries.data(), leaf_nodes.data(), leaf_prims.data());
    stages.leaf_finish_ms = timer.stop_ms();
    meter.release(refs);
    meter.release(leaf_ids[grouped]);
    meter.release(leaves);

    // 8. Emission: sizes and boxes bottom-up, positions top-down, the copy.
    DeviceBuffer<SubtreeSize> sizes("GridBvh: subtree sizes");
    DeviceBuffer<Box3f> node_boxes("GridBvh: hierarchy boxes");
    DeviceBuffer<EmitPosition> at("GridBvh: emission positions");
    meter.allocate(sizes, nodes);
    meter.allocate(node_boxes, nodes);
    meter.allocate(at, nodes);
    const size_t levels = level_offset.size() - 1;
    timer.start();
    for (size_t l = levels; l-- > 0;) {
        const uint32_t first = level_offset[l], end = level_offset[l + 1];
        emit_sizes_kernel<<<blocks_for(end - first), kBlockSize>>>(hnodes.data(), summaries.data(), first, end,
                                                                   sizes.data(), node_boxes.data());
    }
    const SubtreeSize total = download_value(sizes.data());
    const EmitPosition root_at = gridbvh::root_position();
    RF_CUDA_CHECK(cudaMemcpy(at.data(), &root_at, sizeof root_at, cudaMemcpyHostToDevice));
    for (size_t l = 0; l < levels; ++l) {
        const uint32_t first = level_offset[l], end = level_offset[l + 1];
        emit_positions_kernel<<<blocks_for(end - first), kBlockSize>>>(hnodes.data(), sizes.data(), first, end,
                                                                       at.data());
    }
    DeviceBuffer<BvhNode> out_nodes("GridBvh: BVH nodes");
    DeviceBuffer<uint32_t> out_prims("GridBvh: BVH primitive indices");
    meter.allocate(out_nodes, total.nodes);
    meter.allocate(out_prims, total.prims);
    emit_copy_kernel<<<blocks_for(nodes), kBlockSize>>>(hnodes.data(), nodes, node_boxes.data(), at.data(), summaries.data(),
                                                        leaf_begin.data(), leaf_nodes.data(), leaf_prims.data(),
                                                        out_nodes.data(), out_prims.data());
    stages.device_emit_ms = timer.stop_ms();
    stages.peak_device_bytes = meter.peak();

    timer.start();
    bvh.nodes = download_all(out_nodes, total.nodes);
    bvh.prim_indices = download_all(out_prims, total.prims);
    stages.download_ms = timer.stop_ms();
    return true;
}

}  // namespace

Bvh build_grid_bvh_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                             const GridBvhOptions& grid_bvh, bool partial_triangles, DeviceBuildStages* stages,
                             int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    if (triangles.empty()) return build_grid_bvh(triangles, config, grid_bvh, partial_triangles);  // nothing to build
    if (triangles.size() >= (size_t{1} << 30))  // node and leaf links keep their top bit as the leaf flag
        throw Error("GridBvh device build: 2^30 triangles or more");
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    GridHierarchy hierarchy;
    Bvh bvh;
    s.emitted_on_device = build_on_device(triangles, config, grid_bvh, partial_triangles, s, hierarchy, bvh);
    if (s.emitted_on_device) return bvh;
    GridBvhStages host;
    bvh = emit_grid_bvh_hierarchy(triangles, config, partial_triangles, std::move(hierarchy), &host);
    s.leaf_finish_ms += host.leaf_finish_ms;  // device gathering + (host) merging and splitting of leaves
    s.emit_ms = host.emission_ms;            // (host): boxes bottom-up and the canonical layout
    return bvh;
}

}  // namespace rf::cuda
