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
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter
// and live in the scope of the stages that use them. One CUB scratch buffer
// grows over the build and lives to its end.
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
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/launch.h"
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

// kBlockSize (launch.h) is a multiple of 32: every warp is full, so full-mask ballots are valid.
constexpr int kTaskThreads = 8;   // threads per split task (one per bin of an axis)
constexpr int kTasksPerWarp = 32 / kTaskThreads;
constexpr int kTasksPerBlock = kBlockSize / kTaskThreads;
constexpr uint32_t kFullMask = 0xffffffffu;
constexpr uint32_t kMaxQueueBlocks = 4096;  // warps loop over the queue beyond this
constexpr uint32_t kTopCells = uint32_t(gridbvh::kTopRes) * gridbvh::kTopRes * gridbvh::kTopRes;

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

// ---- the host's stages ----

// What lives through the build: the triangles (on the device to its end,
// as they always were), the references and their frame.
struct GridBvhOnDevice {
    uint32_t n = 0;          // triangles
    uint32_t ref_count = 0;  // references, after splitting
    uint32_t leaf_size = 0;
    GridFrame frame;
    DeviceBuffer<Triangle> triangles;
    DeviceBuffer<GridRef> refs;
};

// Stage 1a: one reference per triangle and the scene box (a reduction of
// the reference boxes, freed on return) as the frame. Starts the stage's timer.
void triangle_references(GridBvhOnDevice& g, BuildContext& build, DeviceBuffer<uint8_t>& scratch) {
    g.refs = DeviceBuffer<GridRef>(build.meter, "GridBvh: references", g.n);
    g.ref_count = g.n;
    DeviceBuffer<Box3f> boxes(build.meter, "GridBvh: reference boxes", g.n),
        scene_box(build.meter, "GridBvh: scene box", 1);
    build.timer.start();
    launch(triangle_refs_kernel, g.n, g.triangles.data(), g.n, g.refs.data(), boxes.data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceReduce::Reduce(temp, bytes, boxes.data(), scene_box.data(), g.n, BoxUnion{}, Box3f{});
    });
    g.frame = GridFrame(download_value(scene_box.data()));
}

// The parts one splitting pass writes, one per output slot (empty parts
// where a share was not used), and the count cub::DeviceSelect::If keeps.
struct SplitParts {
    DeviceBuffer<GridRef> parts;
    DeviceBuffer<uint32_t> kept;
};

// Stage 1b's requests and parts: each reference's request, the total
// asked, each one's share of the `available` slots, the output slots by a
// scan, then the parts. No parts when nothing was asked. The requests and
// the slot ends are freed on return.
SplitParts write_parts(const GridBvhOnDevice& g, float max_width, uint64_t available, BuildContext& build,
                       DeviceBuffer<uint8_t>& scratch) {
    const uint32_t count = g.ref_count;
    DeviceBuffer<uint64_t> requests(build.meter, "GridBvhSplit: split requests", count),
        ends(build.meter, "GridBvhSplit: slot ends", count);
    launch(split_request_kernel, count, g.refs.data(), count, max_width, requests.data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::InclusiveSum(temp, bytes, requests.data(), ends.data(), count);
    });
    const uint64_t asked = download_value(ends.data() + count - 1);
    if (asked == 0) return {};
    launch(split_slots_kernel, count, requests.data(), count, asked, available, ends.data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::InclusiveSum(temp, bytes, ends.data(), ends.data(), count);
    });
    const uint64_t slots = download_value(ends.data() + count - 1);
    // Node and leaf links keep their top bit as the leaf flag (kLeafBit).
    if (slots >= (uint64_t{1} << 30)) throw Error("GridBvhSplit device build: more than 2^30 parts");
    SplitParts out{DeviceBuffer<GridRef>(build.meter, "GridBvhSplit: partial triangles", slots),
                   DeviceBuffer<uint32_t>(build.meter, "GridBvhSplit: kept parts", 1)};
    launch(write_parts_kernel, count, g.triangles.data(), g.refs.data(), requests.data(), ends.data(), count, asked,
           available, g.frame, out.parts.data());
    return out;
}

// Stage 1b: one splitting pass (§4.4); the non-empty parts, in order, are
// the new references. False when nothing was wider than the limit (later
// passes would ask nothing either).
bool split_pass(GridBvhOnDevice& g, float max_width, uint64_t available, BuildContext& build,
                DeviceBuffer<uint8_t>& scratch) {
    const SplitParts split = write_parts(g, max_width, available, build, scratch);
    if (split.parts.size() == 0) return false;
    const auto slots = static_cast<int64_t>(split.parts.size());
    g.refs.allocate(split.parts.size());  // reallocated: the old references are freed before the new count
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceSelect::If(temp, bytes, split.parts.data(), g.refs.data(), split.kept.data(), slots,
                                     ValidRef{});
    });
    g.ref_count = download_value(split.kept.data());
    return true;
}

// Stage 1, timed as partial_triangles_ms: the references, the frame and,
// for GridBvhSplit, at most two splitting passes within
// floor(split_budget n) added references.
void make_references(GridBvhOnDevice& g, const GridBvhOptions& grid_bvh, bool partial_triangles, BuildContext& build,
                     DeviceBuffer<uint8_t>& scratch) {
    triangle_references(g, build, scratch);
    const float scene_extent = std::max(g.frame.extent.x, std::max(g.frame.extent.y, g.frame.extent.z));
    const float max_width = scene_extent / 128.0f;  // formula 4.1, sceneDividePortion = 1/128
    const float budget = grid_bvh.split_budget;
    if (partial_triangles && max_width > 0.0f && budget > 0.0f) {
        const uint64_t budget_slots = uint64_t(std::floor(double(budget) * double(g.n)));
        uint64_t used = 0;
        for (int pass = 0; pass < 2 && used < budget_slots; ++pass) {
            const uint32_t before = g.ref_count;
            if (!split_pass(g, max_width, budget_slots - used, build, scratch)) break;
            used += g.ref_count - before;
        }
    }
    build.stages.partial_triangles_ms = build.timer.stop_ms();
    build.stages.references = g.ref_count;
}

// The references' Grid0 keys and ids, sorted by key.
struct SortedCells {
    DeviceBuffer<uint32_t> keys, ids;
};

// Stage 2, timed as sort_ms: 30-bit Grid0 keys of the reference centres,
// sorted once with the reference ids by a stable radix sort; the halves
// that did not end sorted are freed on return.
SortedCells sort_cell_keys(const GridBvhOnDevice& g, BuildContext& build, DeviceBuffer<uint8_t>& scratch) {
    const uint32_t count = g.ref_count;
    DeviceBuffer<uint32_t> keys[2] = {DeviceBuffer<uint32_t>(build.meter, "GridBvh: cell keys", count),
                                      DeviceBuffer<uint32_t>(build.meter, "GridBvh: sorted cell keys", count)};
    DeviceBuffer<uint32_t> ids[2] = {DeviceBuffer<uint32_t>(build.meter, "GridBvh: reference ids", count),
                                     DeviceBuffer<uint32_t>(build.meter, "GridBvh: sorted references", count)};
    build.timer.start();
    launch(cell_keys_kernel, count, g.refs.data(), count, g.frame, keys[0].data(), ids[0].data());
    cub::DoubleBuffer<uint32_t> key_buffers(keys[0].data(), keys[1].data()), id_buffers(ids[0].data(), ids[1].data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceRadixSort::SortPairs(temp, bytes, key_buffers, id_buffers, count, 0, 30);
    });
    build.stages.sort_ms = build.timer.stop_ms();
    const int sorted = key_buffers.Current() == keys[0].data() ? 0 : 1;
    return {std::move(keys[sorted]), std::move(ids[sorted])};
}

// TopGrid0 (128^3 ranks) and the bottom grids: the sparse Grid0.
struct Grid0 {
    uint32_t occupied = 0;  // non-empty top cells
    uint32_t cells = 0;     // non-empty Grid0 cells
    DeviceBuffer<uint32_t> top_index, top_key, top_begin, top_cells, fine_begin;
    DeviceBuffer<unsigned long long> top_mask;
};

// Stage 3a: each sorted position's top-cell and Grid0-cell rank plus one
// (inclusive scans of the flags where the 21-bit and the 30-bit key change;
// the flags are freed on return).
void rank_cells(const uint32_t* sorted_keys, uint32_t count, uint32_t* top_rank, uint32_t* fine_rank,
                BuildContext& build, DeviceBuffer<uint8_t>& scratch) {
    DeviceBuffer<uint32_t> top_flags(build.meter, "GridBvh: top cell starts", count),
        fine_flags(build.meter, "GridBvh: Grid0 cell starts", count);
    launch(cell_start_flags_kernel, count, sorted_keys, count, top_flags.data(), fine_flags.data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::InclusiveSum(temp, bytes, top_flags.data(), top_rank, count);
    });
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::InclusiveSum(temp, bytes, fine_flags.data(), fine_rank, count);
    });
}

// Stage 3, timed as grid0_ms: Grid0 by compaction (§4.2 steps 4-5): the
// ranks (freed on return), then one thread per sorted position scattering
// the first positions, the top keys and the bottom grids' occupancy bits,
// then TopGrid0 by scatter.
Grid0 build_grid0(const SortedCells& sorted, uint32_t count, BuildContext& build, DeviceBuffer<uint8_t>& scratch) {
    DeviceBuffer<uint32_t> top_rank(build.meter, "GridBvh: top cell ranks", count),
        fine_rank(build.meter, "GridBvh: Grid0 cell ranks", count);
    build.timer.start();
    rank_cells(sorted.keys.data(), count, top_rank.data(), fine_rank.data(), build, scratch);
    Grid0 grid;
    grid.occupied = download_value(top_rank.data() + count - 1);
    grid.cells = download_value(fine_rank.data() + count - 1);
    const uint32_t occupied = grid.occupied;
    grid.top_index = DeviceBuffer<uint32_t>(build.meter, "GridBvh: TopGrid0", kTopCells);
    grid.top_key = DeviceBuffer<uint32_t>(build.meter, "GridBvh: top cell keys", occupied);
    grid.top_begin = DeviceBuffer<uint32_t>(build.meter, "GridBvh: top cell starts", size_t{occupied} + 1);
    grid.top_cells = DeviceBuffer<uint32_t>(build.meter, "GridBvh: top cell first Grid0 cells", size_t{occupied} + 1);
    grid.top_mask = DeviceBuffer<unsigned long long>(build.meter, "GridBvh: bottom grid occupancy",
                                                     size_t{occupied} * gridbvh::kMaskWords);
    grid.fine_begin = DeviceBuffer<uint32_t>(build.meter, "GridBvh: Grid0 cell starts", size_t{grid.cells} + 1);
    RF_CUDA_CHECK(cudaMemsetAsync(grid.top_mask.data(), 0, grid.top_mask.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(grid.top_index.data(), 0xff, grid.top_index.bytes()));  // kEmptyCell
    launch(grid0_scatter_kernel, count, sorted.keys.data(), count, top_rank.data(), fine_rank.data(), occupied,
           grid.cells, grid.top_key.data(), grid.top_begin.data(), grid.top_cells.data(), grid.top_mask.data(),
           grid.fine_begin.data());
    launch(top_index_kernel, occupied, grid.top_key.data(), occupied, grid.top_index.data());
    build.stages.grid0_ms = build.timer.stop_ms();
    build.stages.occupied_top_cells = occupied;
    return grid;
}

// The sparse grid EmitHierarchy reads: Grid0 and the count-only levels.
struct SparseGrid {
    Grid0 grid0;
    DeviceBuffer<uint32_t> dense[4];  // Grid4..Grid7
    [[nodiscard]] SparseGridView view() const {
        return {grid0.top_index.data(),
                grid0.top_begin.data(),
                grid0.top_cells.data(),
                reinterpret_cast<const uint64_t*>(grid0.top_mask.data()),
                grid0.fine_begin.data(),
                {dense[0].data(), dense[1].data(), dense[2].data(), dense[3].data()}};
    }
};

// Stage 4, timed as coarse_levels_ms: Grid4 by atomicAdd from the top
// cells, Grid5..Grid7 one thread per cell summing its 8 children (§4.2 step 6).
void count_coarse_levels(SparseGrid& grid, BuildContext& build) {
    const char* const names[4] = {"GridBvh: Grid4", "GridBvh: Grid5", "GridBvh: Grid6", "GridBvh: Grid7"};
    for (int k = 0; k < 4; ++k) {
        const size_t res = size_t(gridbvh::kFineRes) >> (4 + k);
        grid.dense[k] = DeviceBuffer<uint32_t>(build.meter, names[k], res * res * res);
    }
    const Grid0& g0 = grid.grid0;
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(grid.dense[0].data(), 0, grid.dense[0].bytes()));
    launch(grid4_kernel, g0.occupied, g0.top_key.data(), g0.top_begin.data(), g0.occupied, grid.dense[0].data());
    for (int k = 1; k < 4; ++k) {
        const uint32_t res = uint32_t(gridbvh::kFineRes) >> (4 + k);
        launch(coarser_level_kernel, size_t{res} * res * res, grid.dense[k - 1].data(), res, grid.dense[k].data());
    }
    build.stages.coarse_levels_ms = build.timer.stop_ms();
}

// Stages 2-4: the sparse grid of the references. The sorted keys and ids
// live until Grid0 is built: the hierarchy reads counts only, and the
// leaves find their references by descent.
SparseGrid build_sparse_grid(const GridBvhOnDevice& g, BuildContext& build, DeviceBuffer<uint8_t>& scratch) {
    SparseGrid grid;
    {
        const SortedCells sorted = sort_cell_keys(g, build, scratch);
        grid.grid0 = build_grid0(sorted, g.ref_count, build, scratch);
    }
    count_coarse_levels(grid, build);
    return grid;
}

// EmitHierarchy's tree: nodes numbered level by level.
struct Hierarchy {
    DeviceBuffer<uint32_t> hnodes;       // per node: left child, or kLeafBit | leaf
    DeviceBuffer<NodeRegion> regions;    // per node: its IBB at creation
    DeviceBuffer<SplitTask> leaves;      // per leaf: its refined task
    std::vector<uint32_t> level_offset;  // first node of each tree level, plus the node count
    uint32_t leaf_count = 0;
    [[nodiscard]] uint32_t nodes() const { return level_offset.back(); }
};

// Stage 5, timed as hierarchy_ms: EmitHierarchy, one launch per tree level.
// A level holds at most ref_count tasks (disjoint, none empty), the tree
// 2 ref_count - 1 nodes. The grid is spent: it and the queues are freed on return.
Hierarchy emit_hierarchy(SparseGrid grid, const GridBvhOnDevice& g, BuildContext& build) {
    const uint32_t ref_count = g.ref_count;
    const size_t max_nodes = 2 * size_t{ref_count} - 1;
    DeviceBuffer<SplitTask> queue[2] = {DeviceBuffer<SplitTask>(build.meter, "GridBvh: task queue A", ref_count),
                                        DeviceBuffer<SplitTask>(build.meter, "GridBvh: task queue B", ref_count)};
    Hierarchy h{DeviceBuffer<uint32_t>(build.meter, "GridBvh: hierarchy nodes", max_nodes),
                DeviceBuffer<NodeRegion>(build.meter, "GridBvh: hierarchy node regions", max_nodes),
                DeviceBuffer<SplitTask>(build.meter, "GridBvh: hierarchy leaves", ref_count),
                {0}};
    DeviceBuffer<unsigned long long> counters(build.meter, "GridBvh: queue counters", 2);
    const SplitTask root = gridbvh::root_task(ref_count);
    const NodeRegion root_region{root.box, root.level};
    RF_CUDA_CHECK(cudaMemcpy(queue[0].data(), &root, sizeof root, cudaMemcpyHostToDevice));
    RF_CUDA_CHECK(cudaMemcpy(h.regions.data(), &root_region, sizeof root_region, cudaMemcpyHostToDevice));
    const SparseGridView view = grid.view();
    uint32_t count = 1;
    int in = 0;
    build.timer.start();
    while (count != 0) {
        const uint32_t next_base = h.level_offset.back() + count;
        h.level_offset.push_back(next_base);
        RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
        const LevelOutput out{queue[1 - in].data(), h.hnodes.data(), h.regions.data(), h.leaves.data(), next_base,
                              h.leaf_count};
        launch_shaped(split_level_kernel, {strided_blocks_for(count, kMaxQueueBlocks, kTasksPerBlock)}, view, g.frame,
                      queue[in].data(), count, g.leaf_size, out, counters.data());
        const unsigned long long made = download_value(counters.data() + 1);  // waits for the level
        const uint32_t splits = uint32_t(made & 0xffffffffu), new_leaves = uint32_t(made >> 32);
        h.leaf_count += new_leaves;
        count = 2 * splits;
        if (count > ref_count || next_base + size_t{count} > max_nodes || h.leaf_count > ref_count) {
            throw Error("GridBvh device build: task queue overflow");
        }
        in = 1 - in;
    }
    build.stages.hierarchy_ms = build.timer.stop_ms();
    return h;
}

// The references grouped by leaf.
struct LeafGroups {
    DeviceBuffer<uint32_t> refs;   // reference ids by leaf, ascending within a leaf (as the CPU orders them)
    DeviceBuffer<uint32_t> begin;  // per leaf its first position in refs, plus the end
};

// Stage 6a: each reference's leaf by descent, one stable sort of (leaf,
// reference) pairs, the leaf ranges; the leaves of the references and the
// unsorted ids are freed on return. Starts the timer of leaf_finish_ms
// (gathering and finishing).
LeafGroups group_by_leaf(const GridBvhOnDevice& g, const Hierarchy& h, BuildContext& build,
                         DeviceBuffer<uint8_t>& scratch) {
    const uint32_t count = g.ref_count;
    DeviceBuffer<uint32_t> leaf_of[2] = {DeviceBuffer<uint32_t>(build.meter, "GridBvh: leaf of reference", count),
                                         DeviceBuffer<uint32_t>(build.meter, "GridBvh: sorted leaves", count)};
    DeviceBuffer<uint32_t> leaf_ids[2] = {DeviceBuffer<uint32_t>(build.meter, "GridBvh: leaf reference ids", count),
                                          DeviceBuffer<uint32_t>(build.meter, "GridBvh: leaf references", count)};
    LeafGroups groups{{}, DeviceBuffer<uint32_t>(build.meter, "GridBvh: leaf ranges", size_t{h.leaf_count} + 1)};
    int leaf_bits = 1;
    while (leaf_bits < 32 && (h.leaf_count >> leaf_bits) != 0) ++leaf_bits;
    build.timer.start();
    launch(leaf_of_kernel, count, h.hnodes.data(), h.regions.data(), g.frame, g.refs.data(), count,
           leaf_of[0].data(), leaf_ids[0].data());
    cub::DoubleBuffer<uint32_t> leaf_keys(leaf_of[0].data(), leaf_of[1].data()),
        leaf_values(leaf_ids[0].data(), leaf_ids[1].data());
    cub_run(scratch, [&](void* temp, size_t& bytes) {
        return cub::DeviceRadixSort::SortPairs(temp, bytes, leaf_keys, leaf_values, count, 0, leaf_bits);
    });
    launch(leaf_begin_kernel, count, leaf_keys.Current(), count, h.leaf_count, groups.begin.data());
    const int grouped = leaf_values.Current() == leaf_ids[0].data() ? 0 : 1;
    groups.refs = std::move(leaf_ids[grouped]);
    return groups;
}

// Stage 6b: whether every leaf fits one thread (at most kDeviceFinishRefs references).
bool leaves_fit_one_thread(const LeafGroups& groups, uint32_t leaf_count, BuildContext& build) {
    DeviceBuffer<uint32_t> oversized(build.meter, "GridBvh: oversized leaf flag", 1);
    RF_CUDA_CHECK(cudaMemsetAsync(oversized.data(), 0, oversized.bytes()));
    launch(oversized_leaf_kernel, leaf_count, groups.begin.data(), leaf_count, oversized.data());
    return download_value(oversized.data()) == 0;
}

// A leaf too large for one thread: the hierarchy and the leaf groups go
// back to the host, which finishes and emits.
void hand_over_to_host(const GridBvhOnDevice& g, Hierarchy& h, const LeafGroups& groups, BuildContext& build,
                       GridHierarchy& hierarchy) {
    build.stages.leaf_finish_ms = build.timer.stop_ms();  // the host's finishing is added later
    build.stages.peak_device_bytes = build.meter.peak();
    const uint32_t nodes = h.nodes();
    build.timer.start();
    hierarchy.frame = g.frame;
    hierarchy.refs = download_all(g.refs, g.ref_count);
    hierarchy.hnodes = download_all(h.hnodes, nodes);
    hierarchy.regions = download_all(h.regions, nodes);
    hierarchy.leaves = download_all(h.leaves, h.leaf_count);
    hierarchy.level_offset = std::move(h.level_offset);
    hierarchy.leaf_refs = download_all(groups.refs, g.ref_count);
    hierarchy.leaf_begin = download_all(groups.begin, size_t{h.leaf_count} + 1);
    build.stages.download_ms = build.timer.stop_ms();
}

// The finished leaves: per leaf its summary, and its subtree's nodes (at
// 2 leaf_begin) and triangles (at leaf_begin) in slots by reference range.
struct FinishedLeaves {
    DeviceBuffer<LeafSummary> summaries;
    DeviceBuffer<BvhNode> nodes;    // 2 per reference
    DeviceBuffer<uint32_t> prims;   // 1 per reference
};

// Stage 7, ends leaf_finish_ms: one thread per leaf finishes it into its
// slots. The references, the grouped ids and the leaf tasks are spent:
// freed on return.
FinishedLeaves finish_leaves(DeviceBuffer<GridRef> refs, DeviceBuffer<uint32_t> leaf_refs,
                             DeviceBuffer<SplitTask> leaves, const DeviceBuffer<uint32_t>& leaf_begin,
                             uint32_t ref_count, uint32_t leaf_count, const FinishOptions& finish,
                             BuildContext& build) {
    FinishedLeaves out{DeviceBuffer<LeafSummary>(build.meter, "GridBvh: finished leaves", leaf_count),
                       DeviceBuffer<BvhNode>(build.meter, "GridBvh: leaf subtrees", 2 * size_t{ref_count}),
                       DeviceBuffer<uint32_t>(build.meter, "GridBvh: leaf triangles", ref_count)};
    launch(finish_leaves_kernel, leaf_count, refs.data(), leaf_refs.data(), leaf_begin.data(), leaves.data(),
           leaf_count, finish, out.summaries.data(), out.nodes.data(), out.prims.data());
    build.stages.leaf_finish_ms = build.timer.stop_ms();
    return out;
}

// Subtree sizes and boxes bottom-up, then positions top-down, one launch
// per tree level (levelOffset of Algorithm 4.1). Returns the root's size:
// the BVH's.
SubtreeSize size_and_place(const Hierarchy& h, const FinishedLeaves& finished, SubtreeSize* sizes, Box3f* boxes,
                           EmitPosition* at) {
    const size_t levels = h.level_offset.size() - 1;
    for (size_t l = levels; l-- > 0;) {
        const uint32_t first = h.level_offset[l], end = h.level_offset[l + 1];
        launch(emit_sizes_kernel, end - first, h.hnodes.data(), finished.summaries.data(), first, end, sizes, boxes);
    }
    const SubtreeSize total = download_value(sizes);
    const EmitPosition root_at = gridbvh::root_position();
    RF_CUDA_CHECK(cudaMemcpy(at, &root_at, sizeof root_at, cudaMemcpyHostToDevice));
    for (size_t l = 0; l < levels; ++l) {
        const uint32_t first = h.level_offset[l], end = h.level_offset[l + 1];
        launch(emit_positions_kernel, end - first, h.hnodes.data(), sizes, first, end, at);
    }
    return total;
}

// Stage 8, timed as device_emit_ms: the canonical emission, sizes and
// positions then one copy kernel writing the BvhNodes and triangle
// indices; only the BVH is downloaded.
void emit_bvh(const Hierarchy& h, const LeafGroups& groups, const FinishedLeaves& finished, BuildContext& build,
              Bvh& bvh) {
    const uint32_t nodes = h.nodes();
    DeviceBuffer<SubtreeSize> sizes(build.meter, "GridBvh: subtree sizes", nodes);
    DeviceBuffer<Box3f> node_boxes(build.meter, "GridBvh: hierarchy boxes", nodes);
    DeviceBuffer<EmitPosition> at(build.meter, "GridBvh: emission positions", nodes);
    build.timer.start();
    const SubtreeSize total = size_and_place(h, finished, sizes.data(), node_boxes.data(), at.data());
    DeviceBuffer<BvhNode> out_nodes(build.meter, "GridBvh: BVH nodes", total.nodes);
    DeviceBuffer<uint32_t> out_prims(build.meter, "GridBvh: BVH primitive indices", total.prims);
    launch(emit_copy_kernel, nodes, h.hnodes.data(), nodes, node_boxes.data(), at.data(), finished.summaries.data(),
           groups.begin.data(), finished.nodes.data(), finished.prims.data(), out_nodes.data(), out_prims.data());
    build.stages.device_emit_ms = build.timer.stop_ms();
    build.stages.peak_device_bytes = build.meter.peak();

    build.timer.start();
    bvh.nodes = download_all(out_nodes, total.nodes);
    bvh.prim_indices = download_all(out_prims, total.prims);
    build.stages.download_ms = build.timer.stop_ms();
}

// The device pipeline for n >= 1 triangles: returns true with the BVH in
// `bvh` when the device emitted it, false with `hierarchy` filled for the
// host emission when a leaf was too large for one thread.
bool build_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config, const GridBvhOptions& grid_bvh,
                     bool partial_triangles, DeviceBuildStages& stages, GridHierarchy& hierarchy, Bvh& bvh) {
    BuildContext build(stages);
    DeviceBuffer<uint8_t> scratch(build.meter, "GridBvh: CUB temporary storage");  // grows; CUB's, every stage's
    GridBvhOnDevice g;
    g.n = static_cast<uint32_t>(triangles.size());
    g.leaf_size = static_cast<uint32_t>(std::max(1, config.max_leaf_size));
    g.triangles = DeviceBuffer<Triangle>(build.meter, "GridBvh: triangles", g.n);
    build.timer.start();
    g.triangles.upload(triangles);
    stages.upload_ms = build.timer.stop_ms();

    // 1. References, the scene box, partial triangles.
    make_references(g, grid_bvh, partial_triangles, build, scratch);
    // 2-5. The sparse grid, spent by the hierarchy over it.
    Hierarchy h = emit_hierarchy(build_sparse_grid(g, build, scratch), g, build);
    // 6. Leaf gathering.
    LeafGroups groups = group_by_leaf(g, h, build, scratch);
    if (!leaves_fit_one_thread(groups, h.leaf_count, build)) {
        hand_over_to_host(g, h, groups, build, hierarchy);
        return false;
    }
    // 7. Leaf finishing; the regions were for the descent (and the host's emission).
    h.regions.release();
    const FinishOptions finish{g.leaf_size, config.sah.traversal, config.sah.intersection};
    const FinishedLeaves finished = finish_leaves(std::move(g.refs), std::move(groups.refs), std::move(h.leaves),
                                                  groups.begin, g.ref_count, h.leaf_count, finish, build);
    // 8. Emission.
    emit_bvh(h, groups, finished, build, bvh);
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
