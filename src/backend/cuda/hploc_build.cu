// H-PLOC on the device (Benthin, Meister, Barczak, Mohan and Vaidyanathan
// 2024, "H-PLOC: Hierarchical Parallel Locally-Ordered Clustering for
// Bounding Volume Hierarchy Construction", HPG 2024), building
// rf::build_hploc's tree:
//  1. boxes, bounds, 63-bit Morton codes and one stable radix sort
//     (morton_sort.cu, shared with the LBVH, HLBVH2 and PLOC).
//  2. ONE launch, one thread per sorted leaf (the paper's one-kernel build, the
//     steps of accel/bvh/builders/hploc_steps.h on a DeviceWarp: lanes
//     hold their clusters in registers, shuffles move boxes, areas and
//     references between lanes, ballots count and compact): every thread
//     writes its leaf's cluster slot and climbs the implicit LBVH (Apetrei
//     2014) by atomicExch on the boundary slots; ranges of more than 16
//     leaves, and the root, are clustered by their warp with PLOC (Meister
//     and Bittner 2018) down to 16 clusters (one at the root). Nodes are
//     numbered by one atomicAdd per warp and PLOC step, so each node comes
//     after its children and the root is n - 2. A fence before and after
//     each exchange, and after a range's stores, makes a range's clusters
//     and nodes visible to the warp that takes the range over; those reads
//     bypass L1 (__ldcg). The node counter (and a fault flag) come back to
//     the host: 8 bytes, to refuse a clustering that did not make n - 1 nodes.
//  3. emission on the device (raw_tree_emit.cu): boxes, counts, SAH costs
//     and leaf collapse bottom-up, the canonical layout, and the BVH back.
//     A tree deeper than kBvhMaxDepth comes back raw (order, children) and
//     the host finalizes and emits it (emit_hploc_tree). Either way the BVH
//     is build_hploc's: the clusters a range keeps depend only on its
//     children's, whichever warp gets there second.
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter.
#include <cuda_runtime.h>

#include <chrono>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "accel/bvh/builders/hploc.h"
#include "accel/bvh/builders/hploc_steps.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/hploc_build.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

using hploc::kLeafRef;
constexpr uint32_t kFullMask = 0xffffffffu;
static_assert(kBlockSize % hploc::kWarpLanes == 0, "whole warps: every ballot and shuffle has all 32 lanes");

// A value moved between lanes word by word.
template <class T>
__device__ T shuffle_value(const T& value, uint32_t source) {
    static_assert(sizeof(T) % 4 == 0 && std::is_trivially_copyable_v<T>);
    uint32_t words[sizeof(T) / 4];
    memcpy(words, &value, sizeof(T));
    for (uint32_t& word : words) word = __shfl_sync(kFullMask, word, static_cast<int>(source));
    T out;
    memcpy(&out, words, sizeof(T));
    return out;
}

// hploc_steps.h's Warp on a real warp: a lane's value in its registers.
struct DeviceWarp {
    uint32_t lane;

    template <class T>
    struct Lanes {
        T value;
        __device__ T& operator[](uint32_t) { return value; }
        __device__ const T& operator[](uint32_t) const { return value; }
    };

    template <class F>
    __device__ void for_each_lane(F&& f) {
        f(lane);
    }
    template <class F>
    __device__ uint32_t ballot(F&& predicate) {
        return __ballot_sync(kFullMask, predicate(lane));
    }
    template <class T, class F>
    __device__ Lanes<T> shuffle(const Lanes<T>& values, F&& source) {
        return Lanes<T>{shuffle_value(values.value, source(lane))};
    }
    template <class T>
    __device__ T read_lane(const Lanes<T>& values, uint32_t source) {
        return shuffle_value(values.value, source);
    }
    __device__ uint32_t add_once(uint32_t* counter, uint32_t value) {
        uint32_t first = 0;
        if (lane == 0) first = atomicAdd(counter, value);
        return __shfl_sync(kFullMask, first, 0);
    }
    __device__ void sync() { __syncwarp(); }
};

// hploc_steps.h's Memory in global memory. Slots and node boxes other warps
// wrote are read past L1 (not coherent across SMs).
struct DeviceMemory {
    uint32_t* clusters;           // n cluster slots
    const Box3f* triangle_boxes;  // per triangle
    const uint32_t* order;        // sorted position -> triangle
    uint32_t* children;           // 2 (n - 1)
    Box3f* node_boxes;            // n - 1

    __device__ uint32_t load_ref(uint32_t position) const { return __ldcg(clusters + position); }
    __device__ void store_ref(uint32_t position, uint32_t ref) const { __stcg(clusters + position, ref); }
    __device__ Box3f box(uint32_t ref) const {
        if ((ref & kLeafRef) != 0) return triangle_boxes[__ldg(order + (ref & ~kLeafRef))];
        return karras::load_shared_box(node_boxes + ref);
    }
    __device__ void write_node(uint32_t node, uint32_t left, uint32_t right, const Box3f& box) const {
        children[2 * size_t{node}] = left;
        children[2 * size_t{node} + 1] = right;
        node_boxes[node] = box;
    }
    __device__ uint32_t exchange(uint32_t* slot, uint32_t value) const {
        __threadfence();
        const uint32_t before = atomicExch(slot, value);
        __threadfence();
        return before;
    }
    __device__ void publish() const { __threadfence(); }
};

// Stage 2: one thread per leaf, whole warps (lanes past n only help).
__global__ void __launch_bounds__(kBlockSize) hploc_kernel(hploc::Build build, DeviceMemory memory, uint32_t* fault) {
    DeviceWarp warp{threadIdx.x % hploc::kWarpLanes};
    const uint32_t position = blockIdx.x * kBlockSize + threadIdx.x;
    // Before this lane's first exchange, which every reader of the slot comes after.
    if (position < build.n) memory.clusters[position] = kLeafRef | position;
    DeviceWarp::Lanes<hploc::Range> range{hploc::leaf_range(position, build.n)};
    bool failed = false;
    while (hploc::warp_round(warp, memory, build, range, &failed)) {
    }
    if (failed) *fault = 1;
}

double elapsed_ms(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// What the clustering leaves: the nodes, each after its children.
struct HplocNodes {
    DeviceBuffer<uint32_t> children;  // 2 (n - 1)
    DeviceBuffer<Box3f> boxes;        // n - 1
};

// Stage 2 for n >= 2 sorted triangles; its work buffers are freed on return.
HplocNodes cluster(const DeviceMortonOrder<uint64_t>& sorted, uint32_t n, uint32_t radius, BuildContext& build) {
    HplocNodes nodes{DeviceBuffer<uint32_t>(build.meter, "H-PLOC: child references", 2 * size_t{n - 1}),
                     DeviceBuffer<Box3f>(build.meter, "H-PLOC: node boxes", n - 1)};
    DeviceBuffer<uint32_t> clusters(build.meter, "H-PLOC: cluster slots", n);
    DeviceBuffer<uint32_t> boundary_slots(build.meter, "H-PLOC: boundary slots", n - 1);
    DeviceBuffer<uint32_t> counters(build.meter, "H-PLOC: node counter and fault", 2);
    const hploc::Build args{sorted.keys.data(), n, boundary_slots.data(), counters.data(), radius};
    const DeviceMemory memory{clusters.data(), sorted.boxes.data(), sorted.order.data(), nodes.children.data(),
                              nodes.boxes.data()};
    build.timer.start();
    static_assert(hploc::kNoRangeEnd == 0xffffffffu, "boundary slots are cleared bytewise");
    RF_CUDA_CHECK(cudaMemsetAsync(boundary_slots.data(), 0xff, boundary_slots.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(counters.data(), 0, counters.bytes()));
    launch(hploc_kernel, n, args, memory, counters.data() + 1);
    build.stages.hploc_ms = build.timer.stop_ms();
    build.stages.peak_device_bytes = build.meter.peak();
    uint32_t made[2] = {0, 0};
    counters.download(made);
    if (made[1] != 0 || made[0] != n - 1) {
        throw Error("H-PLOC on the device: the clustering made " + std::to_string(made[0]) + " nodes of " +
                    std::to_string(n - 1) + (made[1] != 0 ? ", a range could not be merged" : ""));
    }
    return nodes;
}

// The device pipeline for n >= 2 triangles. `raw`: the node boxes come
// back with the raw tree. Otherwise the device emits the BVH into `bvh` and
// returns true; false when the tree was too deep, and then the raw tree
// came back in `out`.
bool build_on_device(std::span<const Triangle> triangles, uint32_t radius, DeviceBuildStages& stages,
                     DeviceHplocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
                     DeviceBvh* resident = nullptr) {
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    BuildContext build(stages);
    build.resident = resident;
    DeviceMortonOrder<uint64_t> sorted = sort_triangles_by_morton_codes<uint64_t>(triangles, "H-PLOC", build);
    HplocNodes nodes = cluster(sorted, n, radius, build);
    sorted.keys.release();
    if (!raw) {
        nodes.boxes.release();  // the emission computes its own
        DeviceRawTree tree;
        tree.children = nodes.children.data();
        tree.node_slots = n - 1;
        tree.root = n - 2;
        tree.primitives = n;
        tree.boxes = sorted.boxes.data();
        tree.boxes_by_triangle = true;
        tree.order = sorted.order.data();
        if (emit_raw_tree_on_device(tree, *config, "H-PLOC", build, *bvh)) return true;
    }
    build.timer.start();
    out.order = download_all(sorted.order, n);
    out.children = download_all(nodes.children, 2 * size_t{n - 1});
    if (raw) out.node_boxes = download_all(nodes.boxes, n - 1);
    build.stages.download_ms += build.timer.stop_ms();
    return false;
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, int radius, DeviceBuildStages& stages, int device,
               DeviceHplocTree& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
               DeviceBvh* resident = nullptr) {
    if (triangles.size() >= kLeafRef) throw Error("H-PLOC on the device: more than 2^31-1 triangles");
    const size_t n = triangles.size();
    if (n < 2) {  // no merges: nothing for the device to do
        out.order.assign(n, 0u);
        return false;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    return build_on_device(triangles, hploc::clamp_radius(radius), stages, out, raw, config, bvh, resident);
}

}  // namespace

DeviceHplocTree build_hploc_tree_on_device(std::span<const Triangle> triangles, int radius, DeviceBuildStages* stages,
                                           int device) {
    DeviceBuildStages local;
    DeviceHplocTree tree;
    build_raw(triangles, radius, stages ? *stages : local, device, tree, true);
    return tree;
}

Bvh build_hploc_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                          const PlocOptions& ploc_options, DeviceBuildStages* stages, int device,
                          DeviceBvh* resident) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    DeviceHplocTree tree;
    Bvh bvh;
    if (build_raw(triangles, ploc_options.radius, s, device, tree, false, &config, &bvh, resident)) {
        s.emitted_on_device = true;
        return bvh;
    }
    const auto start = std::chrono::steady_clock::now();
    bvh = emit_hploc_tree(triangles, config, std::move(tree.order), tree.children);
    s.emit_ms = elapsed_ms(start);
    return bvh;
}

}  // namespace rf::cuda
