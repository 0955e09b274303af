// HLBVH2 on the device (Garanzha, Pantaleoni and McAllister, HPG 2011;
// Garanzha 2014, dissertation ch. 5, "BVH construction with binary search
// and work queues"), building rf::build_hlbvh2's tree:
//  1. boxes, bounds, 30-bit Morton codes and ONE stable radix sort
//     (morton_sort.cu, shared with the LBVH).
//  2. clusters: a flag per sorted position where the top 15 bits change,
//     cub::DeviceSelect::Flagged of the positions (the cluster starts), then
//     one thread per cluster writes its 15-bit prefix.
//  3. every bottom tree in ONE launch (the paper's work queues, one launch
//     per level, replaced by the radix-tree rule of Karras 2012, sec. 3-4,
//     which HLBVH2's "first 1 of the highest differing bit" split is): one
//     thread per split position i finds, from i alone, the range of the
//     node that splits at i + 1 (hlbvh2_bottom_steps.h node_of_split: the
//     maximal range sharing the bits above the first one where codes i and
//     i + 1 differ, or the halvings of a run of equal codes) and, when that
//     range is over leaf_size, writes inner node i's children (the inner
//     child at its own split_position - 1, or a leaf run) and their parent
//     links; one thread per cluster writes its root. Node i is the CPU's
//     node i (numbered mid - 1), so the trees are the CPU's by
//     construction, whatever the threads' order.
//  4. boxes bottom-up in ONE launch: one thread per leaf walks its parent
//     links, an arrival counter per inner node letting the second child's
//     walk go on (Karras 2012 sec. 4; karras::AtomicArrival, acq_rel), the
//     box union(left, right) as the CPU refit's; a walk reaching a cluster
//     root writes the cluster's box.
//  5. the top level over the clusters by task queues (hlbvh2_top_level.cu:
//     the grid SAH of ch. 4 with the top grid only, 8 lanes per task, the
//     CPU's tree by construction), then the top nodes' boxes bottom-up in
//     one launch (the top level's SAH reads the cluster boxes, so the top
//     boxes cannot join step 4's pass).
//  6. emission on the device (raw_tree_emit.cu): box, count, SAH cost and
//     leaf collapse per node bottom-up, the canonical layout, and the BVH
//     back to the host. Slots no split used are marked (references set to
//     kNoChild before step 3). A tree deeper than kBvhMaxDepth, or one leaf,
//     comes back raw (order, references, clusters, top level) and the host
//     checks, refits and emits it (emit_hlbvh2_forest). Either way the BVH
//     is build_hlbvh2's.
// Stages are timed with CUDA events; buffers are counted by a MemoryMeter
// and live in the scope of the stages that use them.
#include <cuda_runtime.h>

#include <algorithm>
#include <cub/device/device_select.cuh>
#include <string>
#include <thrust/iterator/counting_iterator.h>
#include <utility>
#include <vector>

#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_emit.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_bvh_builders.h"
#include "backend/cuda/hlbvh2_build.h"
#include "backend/cuda/hlbvh2_top_level.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/morton_sort.h"
#include "backend/cuda/raw_tree_emit.h"
#include "rayforge/core/error.h"

namespace rf::cuda {
namespace {

// Stage 2a: 1 where a cluster starts (the top 15 bits change).
__global__ void cluster_flags_kernel(const uint32_t* keys, uint32_t n, uint8_t* flags) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i >= n) return;
    flags[i] = i == 0 || (keys[i] >> hlbvh2::kClusterShift) != (keys[i - 1] >> hlbvh2::kClusterShift);
}

// Stage 2b: one thread per cluster: its 15-bit prefix.
__global__ void cluster_prefix_kernel(const uint32_t* keys, const uint32_t* cluster_begin, uint32_t clusters,
                                      uint32_t* prefix) {
    const uint32_t c = blockIdx.x * kBlockSize + threadIdx.x;
    if (c < clusters) prefix[c] = keys[cluster_begin[c]] >> hlbvh2::kClusterShift;
}

// Stage 3: every bottom tree at once: threads 0 .. n - 2 the split
// positions (inner node i, if any, writes its children), then one per
// cluster (its root's reference).
__global__ void bottom_trees_kernel(const uint32_t* keys, uint32_t n, const uint32_t* cluster_begin,
                                    uint32_t clusters, uint32_t leaf_size, hlbvh2::BottomTrees out) {
    const uint32_t t = blockIdx.x * kBlockSize + threadIdx.x;
    if (t < n - 1) {
        hlbvh2::build_split_node(keys, n, t, leaf_size, out);
    } else if (t - (n - 1) < clusters) {
        const uint32_t c = t - (n - 1);
        const uint32_t end = c + 1 < clusters ? cluster_begin[c + 1] : n;
        hlbvh2::build_cluster_root(keys, n, c, cluster_begin[c], end, leaf_size, out);
    }
}

// Stage 4: the bottom trees' boxes and the clusters', one thread per sorted
// position (those that start a leaf walk up).
__global__ void bottom_boxes_kernel(hlbvh2::BottomBoxPass pass, uint32_t n) {
    const uint32_t i = blockIdx.x * kBlockSize + threadIdx.x;
    if (i < n) hlbvh2::boxes_from_leaf<karras::AtomicArrival>(pass, i);
}

// What lives to the end of a build: the sorted triangles, the bottom
// trees (references, leaf runs) and the top level.
struct ForestOnDevice {
    uint32_t n = 0, clusters = 0;
    DeviceMortonOrder<uint32_t> sorted;
    DeviceBuffer<uint32_t> refs;  // 2 (n - 1) split slots, then the cluster roots
    DeviceBuffer<uint8_t> leaf_runs;
    DeviceTopLevel top;
    [[nodiscard]] size_t ref_count() const { return 2 * (size_t{n} - 1) + clusters; }
    [[nodiscard]] const uint32_t* cluster_roots() const { return refs.data() + 2 * (size_t{n} - 1); }
};

// Runs of equal 15-bit prefixes of the sorted codes.
struct Clusters {
    DeviceBuffer<uint32_t> begin;   // first sorted position of each
    DeviceBuffer<uint32_t> prefix;  // 15-bit prefix of each
};

// Stage 2a, timed: flags where the prefix changes, compacted into the
// cluster starts (`begin`, room for n). The flags, the count and the
// scratch are allocated before the timer and freed after it. Returns the
// cluster count (read once the timed work is done).
uint32_t compact_cluster_starts(const ForestOnDevice& f, DeviceBuffer<uint32_t>& begin, BuildContext& build) {
    const uint32_t n = f.n;
    DeviceBuffer<uint8_t> flags(build.meter, "HLBVH2: cluster flags", n);
    DeviceBuffer<uint32_t> selected(build.meter, "HLBVH2: cluster count", 1);
    DeviceBuffer<uint8_t> scratch(build.meter, "HLBVH2: cluster compaction temporary storage");
    const thrust::counting_iterator<uint32_t> positions(0u);
    const auto select = [&](void* temp, size_t& bytes) {
        return cub::DeviceSelect::Flagged(temp, bytes, positions, flags.data(), begin.data(), selected.data(), n);
    };
    cub_reserve(scratch, select);
    build.timer.start();
    launch(cluster_flags_kernel, n, f.sorted.keys.data(), n, flags.data());
    cub_run(scratch, select);
    build.stages.clusters_ms = build.timer.stop_ms();
    return download_value(selected.data());
}

// Stage 2, timed as clusters_ms: the clusters and their prefixes.
// Allocations stay outside the timed work.
Clusters find_clusters(ForestOnDevice& f, BuildContext& build) {
    Clusters found;
    found.begin = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: cluster starts", f.n);  // at most one per triangle
    f.clusters = compact_cluster_starts(f, found.begin, build);
    build.stages.cluster_count = f.clusters;
    found.prefix = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: cluster prefixes", f.clusters);
    build.timer.start();
    launch(cluster_prefix_kernel, f.clusters, f.sorted.keys.data(), found.begin.data(), f.clusters,
           found.prefix.data());
    build.stages.clusters_ms += build.timer.stop_ms();
    return found;
}

// The bottom trees' parent links, for the box pass.
struct ParentLinks {
    DeviceBuffer<uint32_t> inner;  // per inner node index
    DeviceBuffer<uint32_t> leaf;   // per sorted position: kNoParent unless a leaf starts there
};

// Stage 3, timed as bottom_ms: every bottom tree in one launch into f.refs
// and f.leaf_runs (hlbvh2_bottom_steps.h build_split_node: the node numbers
// are the CPU's by construction, whatever the threads' order). The sorted
// codes are spent, freed on return. Returns the parent links.
ParentLinks build_bottom_trees(ForestOnDevice& f, DeviceBuffer<uint32_t> sorted_keys, const Clusters& found,
                               uint32_t leaf_size, BuildContext& build) {
    f.refs = DeviceBuffer<uint32_t>(build.meter, "HLBVH2: child references", f.ref_count());
    f.leaf_runs = DeviceBuffer<uint8_t>(build.meter, "HLBVH2: leaf run sizes", f.n);
    ParentLinks parents{DeviceBuffer<uint32_t>(build.meter, "HLBVH2: inner node parents", f.n - 1),
                        DeviceBuffer<uint32_t>(build.meter, "HLBVH2: leaf parents", f.n)};
    const hlbvh2::BottomTrees out{f.refs.data(), f.leaf_runs.data(), parents.inner.data(), parents.leaf.data()};
    build.timer.start();
    // Split positions no node has leave their slots unused: marked for the emission.
    RF_CUDA_CHECK(cudaMemsetAsync(f.refs.data(), 0xff, f.refs.bytes()));
    RF_CUDA_CHECK(cudaMemsetAsync(parents.leaf.data(), 0xff, parents.leaf.bytes()));  // kNoParent
    launch(bottom_trees_kernel, uint64_t{f.n} - 1 + f.clusters, sorted_keys.data(), f.n, found.begin.data(),
           f.clusters, leaf_size, out);
    build.stages.bottom_ms = build.timer.stop_ms();
    build.stages.bottom_levels = 1;  // one launch for every level
    return parents;
}

// The bottom trees' boxes.
struct ForestBoxes {
    DeviceBuffer<Box3f> inner;     // per inner node
    DeviceBuffer<Box3f> clusters;  // per cluster
    [[nodiscard]] hlbvh2::BoxView view(const ForestOnDevice& f) const {
        return {f.refs.data(), f.leaf_runs.data(), f.sorted.order.data(), f.sorted.boxes.data(), inner.data()};
    }
};

// Stage 4, timed as boxes_ms: the bottom trees' and the clusters' boxes in
// one bottom-up launch with an arrival counter per inner node; the parent
// links are spent, freed on return.
ForestBoxes box_bottom_trees(const ForestOnDevice& f, ParentLinks parents, BuildContext& build) {
    ForestBoxes boxes{DeviceBuffer<Box3f>(build.meter, "HLBVH2: inner node boxes", f.n - 1),
                      DeviceBuffer<Box3f>(build.meter, "HLBVH2: cluster boxes", f.clusters)};
    DeviceBuffer<uint32_t> arrivals(build.meter, "HLBVH2: inner node arrival counters", f.n - 1);
    const hlbvh2::BottomBoxPass pass{boxes.view(f), parents.inner.data(), parents.leaf.data(), arrivals.data(),
                                     boxes.clusters.data()};
    build.timer.start();
    RF_CUDA_CHECK(cudaMemsetAsync(arrivals.data(), 0, arrivals.bytes()));
    launch(bottom_boxes_kernel, f.n, pass, f.n);
    build.stages.boxes_ms = build.timer.stop_ms();
    return boxes;
}

// Stage 5: the top level over the clusters (hlbvh2_top_level.cu).
DeviceTopLevel build_top_level(const ForestOnDevice& f, const Clusters& found, const ForestBoxes& boxes,
                               BuildContext& build) {
    DeviceTopLevelInput input;
    input.n = f.n;
    input.clusters = f.clusters;
    input.cluster_begin = found.begin.data();
    input.cluster_prefix = found.prefix.data();
    input.cluster_boxes = boxes.clusters.data();
    input.cluster_roots = f.cluster_roots();
    input.bottom = boxes.view(f);
    return build_top_level_on_device(input, build);
}

// Stage 6: the emission on the device, of the tree alone.
bool emit_on_device(const ForestOnDevice& f, uint32_t root, const BvhBuildConfig& config, BuildContext& build,
                    Bvh& bvh) {
    DeviceRawTree tree;
    tree.children = f.refs.data();
    tree.high_children = f.clusters >= 2 ? f.top.top_refs.data() : nullptr;
    tree.high_base = f.n - 1;
    tree.node_slots = f.n - 1 + (f.clusters - 1);
    tree.root = root;
    tree.primitives = f.n;
    tree.boxes = f.sorted.boxes.data();
    tree.boxes_by_triangle = true;
    tree.order = f.sorted.order.data();
    tree.leaf_runs = f.leaf_runs.data();
    tree.sparse_slots = true;  // leaf runs leave most split positions without a node
    return emit_raw_tree_on_device(tree, config, "HLBVH2", build, bvh);
}

// The raw tree for the host's refit and emission, timed into download_ms:
// the order, the references, the clusters (unless taken already: `found`
// null) and the top level; with `raw_boxes`, the boxes and level sizes of
// the raw forest too.
void download_forest(const ForestOnDevice& f, const Clusters* found, const ForestBoxes* raw_boxes,
                     BuildContext& build, DeviceHlbvh2Forest& out) {
    build.timer.start();
    out.forest.order = download_all(f.sorted.order, f.n);
    out.forest.refs = download_all(f.refs, f.ref_count());
    if (found != nullptr) {
        out.forest.cluster_begin = download_all(found->begin, f.clusters);
        out.forest.cluster_prefix = download_all(found->prefix, f.clusters);
    }
    out.forest.cluster_begin.push_back(f.n);
    if (f.clusters >= 2) out.forest.top_refs = download_all(f.top.top_refs, 2 * (size_t{f.clusters} - 1));
    if (raw_boxes != nullptr) {
        out.cluster_boxes = download_all(raw_boxes->clusters, f.clusters);
        if (f.clusters >= 2) out.top_boxes = download_all(f.top.top_boxes, f.clusters - 1);
        out.top_level_sizes = f.top.level_sizes;
    }
    build.stages.download_ms += build.timer.stop_ms();
}

// The device pipeline for n >= 2 triangles. `raw`: the raw forest comes
// back whole. Otherwise, with `config`, the device emits the BVH into `bvh`
// and returns true; false when it could not (too deep, or one leaf), and
// then the forest came back in `out`.
bool build_forest(std::span<const Triangle> triangles, uint32_t leaf_size, DeviceBuildStages& stages,
                  DeviceHlbvh2Forest& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
                  DeviceBvh* resident = nullptr) {
    BuildContext build(stages);
    build.resident = resident;
    ForestOnDevice f;
    f.n = static_cast<uint32_t>(triangles.size());
    // 1. Boxes, bounds, codes, the sort.
    f.sorted = sort_triangles_by_morton_codes<uint32_t>(triangles, "HLBVH2", build);
    uint32_t root = f.n - 1;
    {
        // 2-5. The clusters and the boxes live in this scope: the device emission reads neither.
        Clusters found = find_clusters(f, build);
        ParentLinks parents = build_bottom_trees(f, std::move(f.sorted.keys), found, leaf_size, build);
        const ForestBoxes boxes = box_bottom_trees(f, std::move(parents), build);
        if (f.clusters >= 2) f.top = build_top_level(f, found, boxes, build);
        stages.peak_device_bytes = build.meter.peak();
        if (!raw && f.clusters < 2) root = download_value(f.cluster_roots());
        if (raw || (root & hlbvh2::kLeafRef) != 0) {
            download_forest(f, &found, raw ? &boxes : nullptr, build, out);
            return false;
        }
        // The host's fallback gets the clusters from here.
        out.forest.cluster_begin = download_all(found.begin, f.clusters);
        out.forest.cluster_prefix = download_all(found.prefix, f.clusters);
    }
    // 6. Emission on the device.
    if (emit_on_device(f, root, *config, build, *bvh)) return true;
    download_forest(f, nullptr, nullptr, build, out);
    return false;
}

// Returns true when the device emitted the BVH into *bvh (config and bvh given).
bool build_raw(std::span<const Triangle> triangles, uint32_t leaf_size, DeviceBuildStages& stages, int device,
               DeviceHlbvh2Forest& out, bool raw, const BvhBuildConfig* config = nullptr, Bvh* bvh = nullptr,
               DeviceBvh* resident = nullptr) {
    if (triangles.size() >= hlbvh2::kLeafRef / 2) throw Error("HLBVH2 device build: more than 2^30-1 triangles");
    if (leaf_size < 1 || leaf_size > 255) throw Error("HLBVH2 device build: leaf size must be in [1, 255]");
    if (triangles.size() < 2) return false;  // no inner nodes: the host does it
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    return build_forest(triangles, leaf_size, stages, out, raw, config, bvh, resident);
}

}  // namespace

DeviceHlbvh2Forest build_hlbvh2_forest_on_device(std::span<const Triangle> triangles, uint32_t leaf_size,
                                                 DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceHlbvh2Forest forest;
    build_raw(triangles, leaf_size, stages ? *stages : local, device, forest, true);
    return forest;
}

Bvh build_hlbvh2_on_device(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                           DeviceBuildStages* stages, int device, DeviceBvh* resident) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    if (triangles.size() < 2) return build_hlbvh2(triangles, config);  // 0 or 1 triangles: nothing to queue
    DeviceHlbvh2Forest raw;
    Bvh bvh;
    if (build_raw(triangles, static_cast<uint32_t>(std::max(config.max_leaf_size, 1)), s, device, raw, false,
                  &config, &bvh, resident)) {
        s.emitted_on_device = true;
        return bvh;
    }
    Hlbvh2Stages host;
    bvh = emit_hlbvh2_forest(triangles, config, std::move(raw.forest), &host);
    s.emit_ms = host.top_ms + host.emit_ms;  // the host checks and finalizes the device's top level
    return bvh;
}

}  // namespace rf::cuda
