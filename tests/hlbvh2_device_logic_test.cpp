// The per-task logic of the CUDA HLBVH2 (Garanzha 2014 ch. 5; src/accel/bvh/
// build/hlbvh2_bottom_steps.h) run on the CPU the way the kernels run it: one
// launch per level, each "warp" dequeuing 32 tasks at once from the input
// queue, its lanes splitting with process_task, new tasks placed by the
// warp-local prefix sum (enqueue_offset) after one add on the output tail,
// queues ping-pong; warps are scheduled in a shuffled order. Checks the
// forest against an independent top-down reference (same node indices, same
// children), that every primitive is in exactly one leaf, the level-wise
// bottom-up boxes, and that the host emission (emit_hlbvh2_forest, the
// device build's host half) gives build_hlbvh2's BVH. A wrong split must fail.
// The top level (hlbvh2_top_steps.h; backend/cuda/hlbvh2_top_level.cu) is run
// the same way: one launch per level, 4 tasks per warp, 8 lanes per task
// whose shuffles (butterfly bounds, prefix/suffix bin scans, the candidate
// fold) and ballots (the stable partition, the enqueue) are emulated lane by
// lane, warps shuffled; its references must be the CPU's top level
// (build_hlbvh2_top_level) and, emitted, give build_hlbvh2's BVH. A wrong
// tie rule must fail. Large tasks take the block path (one block per task:
// strided binning by shared-memory atomics on ordered float keys, emulated
// in shuffled thread orders; the partition by a block scan); its merged bins
// must equal bin_task's, its tree the CPU's, and a wrong stride must fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/hlbvh2_emit.h"
#include "accel/bvh/builders/hlbvh2_bottom_steps.h"
#include "accel/bvh/builders/hlbvh2_top_steps.h"
#include "accel/bvh/builders/morton_tree.h"
#include "accel_test_scenes.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using hlbvh2::kLeafRef;
using hlbvh2::Task;

constexpr uint32_t kUnset = 0xdeadbeefu;
constexpr uint32_t kWarp = 32;

bool same_box(const Box3f& a, const Box3f& b) { return std::memcmp(&a, &b, sizeof(Box3f)) == 0; }

// What the device has after the sort and the cluster compaction.
struct SortedClusters {
    std::vector<uint32_t> keys, order;
    std::vector<Box3f> triangle_boxes;  // per triangle
    std::vector<uint32_t> cluster_begin, cluster_prefix;
};

SortedClusters sort_and_cluster(std::span<const Triangle> triangles) {
    morton::RawTree tree(triangles, BvhBuildConfig{});
    morton::Buffer<uint32_t> keys;
    tree.sort_by_morton_codes(keys);
    SortedClusters s;
    const uint32_t n = tree.size();
    s.keys.assign(keys.data(), keys.data() + n);
    s.order = tree.order;
    s.triangle_boxes.resize(n);
    for (uint32_t i = 0; i < n; ++i) s.triangle_boxes[s.order[i]] = tree.boxes[i];
    for (uint32_t i = 0; i < n; ++i) {
        if (i == 0 || (s.keys[i] >> hlbvh2::kClusterShift) != (s.keys[i - 1] >> hlbvh2::kClusterShift)) {
            s.cluster_begin.push_back(i);
            s.cluster_prefix.push_back(s.keys[i] >> hlbvh2::kClusterShift);
        }
    }
    s.cluster_begin.push_back(n);
    return s;
}

// A task step with the split moved one position right where possible: the bug the checks must catch.
uint32_t process_task_wrong_split(const uint32_t* codes, const Task& task, uint32_t leaf_size, uint32_t* refs,
                                  uint8_t* leaf_runs, Task* inner_children, uint32_t* node) {
    const uint32_t inner = hlbvh2::process_task(codes, task, leaf_size, refs, leaf_runs, inner_children, node);
    if (*node == hlbvh2::kNoNode) return inner;
    const uint32_t mid = *node + 2;  // the right split is *node + 1
    if (mid >= task.end) return inner;
    // Redo the node with mid + 1.
    const uint32_t index = mid - 1;
    refs[task.slot] = index;
    *node = index;
    const Task halves[2] = {{task.first, mid, 2 * index}, {mid, task.end, 2 * index + 1}};
    uint32_t count = 0;
    for (const Task& h : halves) {
        if (h.end - h.first <= leaf_size) {
            refs[h.slot] = kLeafRef | h.first;
            leaf_runs[h.first] = static_cast<uint8_t>(h.end - h.first);
        } else {
            inner_children[count++] = h;
        }
    }
    return count;
}

using ProcessTask = uint32_t (*)(const uint32_t*, const Task&, uint32_t, uint32_t*, uint8_t*, Task*, uint32_t*);

struct QueueForest {
    std::vector<uint32_t> refs;
    std::vector<uint8_t> leaf_runs;
    std::vector<std::vector<uint32_t>> level_nodes;  // per level, one entry per task (kNoNode for leaves)
    std::vector<uint32_t> level_sizes;
};

// The work-queue kernels, level by level, warps in a shuffled order.
QueueForest run_work_queues(const SortedClusters& s, uint32_t leaf_size, uint32_t seed,
                            ProcessTask process = hlbvh2::process_task) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
    QueueForest f;
    f.refs.assign(2 * size_t{n - 1} + clusters, kUnset);
    f.leaf_runs.assign(n, 0);
    std::vector<Task> queue[2];
    for (uint32_t c = 0; c < clusters; ++c) {
        queue[0].push_back({s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c});  // level 0: the clusters
    }
    std::mt19937 rng(seed);
    int in = 0;
    while (!queue[in].empty()) {
        const std::vector<Task>& input = queue[in];
        std::vector<Task>& output = queue[1 - in];
        output.assign(2 * input.size(), Task{kUnset, kUnset, kUnset});
        uint32_t tail = 0;  // the output queue's atomic counter
        std::vector<uint32_t> nodes(input.size(), kUnset);
        // Warps dequeue 32 tasks each (one add on the head); which warp gets
        // which chunk is up to the hardware: shuffle.
        std::vector<uint32_t> chunks((input.size() + kWarp - 1) / kWarp);
        std::iota(chunks.begin(), chunks.end(), 0u);
        std::shuffle(chunks.begin(), chunks.end(), rng);
        for (uint32_t chunk : chunks) {
            Task children[kWarp][2];
            uint32_t counts[kWarp] = {};
            uint32_t one_or_more = 0, two = 0;
            for (uint32_t lane = 0; lane < kWarp; ++lane) {
                const size_t at = size_t{chunk} * kWarp + lane;
                if (at >= input.size()) continue;
                counts[lane] = process(s.keys.data(), input[at], leaf_size, f.refs.data(), f.leaf_runs.data(),
                                       children[lane], &nodes[at]);
                one_or_more |= (counts[lane] >= 1 ? 1u : 0u) << lane;
                two |= (counts[lane] == 2 ? 1u : 0u) << lane;
            }
            const uint32_t base = tail;  // lane 0's atomicAdd
            tail += hlbvh2::enqueue_total(one_or_more, two);
            for (uint32_t lane = 0; lane < kWarp; ++lane) {
                const uint32_t offset = hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(lane));
                for (uint32_t k = 0; k < counts[lane]; ++k) output[base + offset + k] = children[lane][k];
            }
        }
        output.resize(tail);
        f.level_sizes.push_back(static_cast<uint32_t>(input.size()));
        f.level_nodes.push_back(std::move(nodes));
        queue[in].clear();
        in = 1 - in;
    }
    return f;
}

// Independent reference: the bottom trees top-down, the split found by a
// linear scan for the first code with the highest differing bit set.
void reference_range(const std::vector<uint32_t>& keys, uint32_t a, uint32_t b, uint32_t slot, uint32_t leaf_size,
                     std::vector<uint32_t>& refs) {
    if (b - a <= leaf_size) {
        refs[slot] = kLeafRef | a;
        return;
    }
    uint32_t mid = a + (b - a) / 2;
    const uint32_t differ = keys[a] ^ keys[b - 1];
    if (differ != 0) {
        const int bit = std::bit_width(differ) - 1;
        mid = a;
        while (((keys[mid] >> bit) & 1u) == 0) ++mid;
    }
    refs[slot] = mid - 1;
    reference_range(keys, a, mid, 2 * (mid - 1), leaf_size, refs);
    reference_range(keys, mid, b, 2 * (mid - 1) + 1, leaf_size, refs);
}

// Walks the forest from the cluster roots; counts how often each primitive
// is reached through a leaf, and compares every reached slot with `expected`.
void walk(const std::vector<uint32_t>& refs, const std::vector<uint8_t>& leaf_runs, const std::vector<uint32_t>& expected,
          uint32_t ref, std::vector<uint32_t>& seen, size_t& wrong) {
    if (ref & kLeafRef) {
        const uint32_t first = ref & ~kLeafRef;
        for (uint32_t i = 0; i < leaf_runs[first]; ++i) ++seen[first + i];
        return;
    }
    for (int side = 0; side < 2; ++side) {
        const uint32_t slot = 2 * ref + side;
        wrong += refs[slot] != expected[slot];
        walk(refs, leaf_runs, expected, refs[slot], seen, wrong);
    }
}

struct NamedScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<NamedScene> scenes() {
    std::vector<NamedScene> out;
    out.push_back({"soup", test::make_triangle_soup(20000, 1, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f)});
    out.push_back({"sphere", test::to_geometry(test::make_icosphere(4))});
    out.push_back({"nasty", test::make_nasty_geometry(2)});
    SceneGeometry point;  // every triangle in one point: all codes equal, one cluster
    for (int i = 0; i < 1000; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    out.push_back({"one point", std::move(point)});
    SceneGeometry lattice;  // 4^3 tiny triangles on a lattice: every cluster one triangle
    for (int x = 0; x < 4; ++x) {
        for (int y = 0; y < 4; ++y) {
            for (int z = 0; z < 4; ++z) {
                const Vec3f p{static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
                test::append(lattice, {p, p + Vec3f(0.01f, 0, 0), p + Vec3f(0, 0.01f, 0)});
            }
        }
    }
    out.push_back({"singleton clusters", std::move(lattice)});
    SceneGeometry two;
    test::append(two, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    test::append(two, {Vec3f(0, 0, 2), Vec3f(1, 0, 2), Vec3f(0, 1, 2)});
    out.push_back({"two", std::move(two)});
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    out.push_back({"one", std::move(one)});
    return out;
}

Hlbvh2Forest to_forest(const SortedClusters& s, const QueueForest& f, std::vector<uint32_t> top_refs = {}) {
    return {s.order, f.refs, s.cluster_begin, s.cluster_prefix, std::move(top_refs)};
}

bool same_bvh(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() && a.prim_indices == b.prim_indices &&
           (a.nodes.empty() || std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(a.nodes[0])) == 0);
}

TEST(Hlbvh2DeviceLogic, WorkQueuesBuildTheCpuBottomTrees) {
    for (const NamedScene& scene : scenes()) {
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const uint32_t n = static_cast<uint32_t>(s.keys.size());
            const uint32_t clusters = static_cast<uint32_t>(s.cluster_prefix.size());
            std::vector<uint32_t> expected(2 * size_t{n - 1} + clusters, kUnset);
            for (uint32_t c = 0; c < clusters; ++c) {
                reference_range(s.keys, s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c, leaf_size,
                                expected);
            }
            for (uint32_t seed : {1u, 2u}) {
                const QueueForest f = run_work_queues(s, leaf_size, seed);
                std::vector<uint32_t> seen(n, 0);
                size_t wrong = 0;
                for (uint32_t c = 0; c < clusters; ++c) {
                    const uint32_t slot = 2 * (n - 1) + c;
                    wrong += f.refs[slot] != expected[slot];
                    walk(f.refs, f.leaf_runs, expected, f.refs[slot], seen, wrong);
                }
                EXPECT_EQ(wrong, 0u) << "references that differ from the reference";
                EXPECT_EQ(std::count(seen.begin(), seen.end(), 1u), static_cast<long>(n)) << "primitives not in exactly one leaf";
                EXPECT_EQ(f.level_sizes.front(), clusters);
                // Level l >= 1 holds only inner tasks, each a distinct node.
                size_t inner = 0;
                for (const auto& level : f.level_nodes) {
                    inner += std::count_if(level.begin(), level.end(), [](uint32_t v) { return v != hlbvh2::kNoNode; });
                }
                const size_t expected_inner = std::count_if(expected.begin(), expected.end(), [](uint32_t r) {
                    return r != kUnset && (r & kLeafRef) == 0;
                });
                EXPECT_EQ(inner, expected_inner);
            }
        }
    }
}

TEST(Hlbvh2DeviceLogic, LevelWiseBoxesAreUnionsOfChildren) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(5000, 3, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.1f).triangles);
    const QueueForest f = run_work_queues(s, 4, 7);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Box3f poison;
    poison.lo = Vec3f(1e30f);
    poison.hi = Vec3f(-1e30f);
    std::vector<Box3f> inner_boxes(n - 1, poison);
    const hlbvh2::BoxView view{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                               inner_boxes.data()};
    for (size_t l = f.level_nodes.size(); l-- > 0;) {  // deepest level first, one launch each
        for (uint32_t node : f.level_nodes[l]) {
            if (node != hlbvh2::kNoNode) hlbvh2::node_box(view, node);
        }
    }
    // Against the boxes of the primitives below each cluster root.
    size_t wrong = 0;
    for (size_t c = 0; c + 1 < s.cluster_begin.size(); ++c) {
        Box3f expected = s.triangle_boxes[s.order[s.cluster_begin[c]]];
        for (uint32_t i = s.cluster_begin[c]; i < s.cluster_begin[c + 1]; ++i) {
            expected = hlbvh2::box_union(expected, s.triangle_boxes[s.order[i]]);
        }
        wrong += !same_box(hlbvh2::reference_box(view, f.refs[2 * (n - 1) + c]), expected);
    }
    EXPECT_EQ(wrong, 0u);
}

TEST(Hlbvh2DeviceLogic, HostEmissionIsBuildHlbvh2) {
    for (const NamedScene& scene : scenes()) {
        for (int leaf_size : {1, 4, 8}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const BvhBuildConfig config{.max_leaf_size = leaf_size};
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            const QueueForest f = run_work_queues(s, static_cast<uint32_t>(leaf_size), 11);
            Hlbvh2Stages stages;
            const Bvh got = emit_hlbvh2_forest(scene.geometry.triangles, config, to_forest(s, f), &stages);
            EXPECT_TRUE(same_bvh(build_hlbvh2(scene.geometry.triangles, config), got));
        }
    }
    EXPECT_TRUE(emit_hlbvh2_forest({}, {}, Hlbvh2Forest{}).nodes.empty());
}

TEST(Hlbvh2DeviceLogic, EnqueueOffsetsArePrefixSums) {
    std::mt19937 rng(5);
    for (int round = 0; round < 100; ++round) {
        uint32_t counts[kWarp], one_or_more = 0, two = 0, sum = 0;
        for (uint32_t lane = 0; lane < kWarp; ++lane) {
            counts[lane] = rng() % 3;
            one_or_more |= (counts[lane] >= 1 ? 1u : 0u) << lane;
            two |= (counts[lane] == 2 ? 1u : 0u) << lane;
        }
        for (uint32_t lane = 0; lane < kWarp; ++lane) {
            ASSERT_EQ(hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(lane)), sum);
            sum += counts[lane];
        }
        ASSERT_EQ(hlbvh2::enqueue_total(one_or_more, two), sum);
    }
}

TEST(Hlbvh2DeviceLogic, WrongSplitIsCaught) {
    const SceneGeometry g = test::make_triangle_soup(3000, 9, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.5f);
    const BvhBuildConfig config{.max_leaf_size = 1};
    const SortedClusters s = sort_and_cluster(g.triangles);
    const QueueForest f = run_work_queues(s, 1, 3, process_task_wrong_split);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    size_t differ = 0;
    for (size_t c = 0; c + 1 < s.cluster_begin.size(); ++c) {
        std::vector<uint32_t> expected(f.refs.size(), kUnset);
        reference_range(s.keys, s.cluster_begin[c], s.cluster_begin[c + 1], 2 * (n - 1) + c, 1, expected);
        std::vector<uint32_t> seen(n, 0);
        differ += f.refs[2 * (n - 1) + c] != expected[2 * (n - 1) + c];
        walk(f.refs, f.leaf_runs, expected, f.refs[2 * (n - 1) + c], seen, differ);
    }
    EXPECT_GT(differ, 0u);
    EXPECT_FALSE(same_bvh(build_hlbvh2(g.triangles, config),
                          emit_hlbvh2_forest(g.triangles, config, to_forest(s, f))));
}

TEST(Hlbvh2DeviceLogic, MalformedForestThrows) {
    const SceneGeometry g = test::make_triangle_soup(500, 4, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    const SortedClusters s = sort_and_cluster(g.triangles);
    const QueueForest f = run_work_queues(s, 1, 1);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    Hlbvh2Forest bad = to_forest(s, f);
    // A cluster root pointing at a leaf that is not its range's start.
    bad.refs[2 * (n - 1)] = kLeafRef | 1u;
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, BvhBuildConfig{.max_leaf_size = 1}, std::move(bad)), Error);
}

// ---- The top level ----

using hlbvh2::TopBin;
using hlbvh2::TopCluster;
using hlbvh2::TopTask;
constexpr uint32_t kLanes = hlbvh2::kTopLanes;
constexpr uint32_t kTasksPerWarp = kWarp / kLanes;

// The tie rule the checks must catch: a later candidate of equal cost wins.
bool consider_last_of_equals(hlbvh2::TopSplit& best, float cost, int axis, uint32_t plane) {
    if (best.axis >= 0 && !(cost <= best.cost)) return false;
    best = {cost, axis, plane};
    return true;
}
using Consider = bool (*)(hlbvh2::TopSplit&, float, int, uint32_t);

// choose_split_lanes of hlbvh2_top_level.cu, its 8 lanes in lockstep
// (bins[lane][axis]: lane's bin of each axis; the lanes' bounds are equal).
hlbvh2::TopSplit emulate_split_lanes(const TopBin bins[kLanes][3], const hlbvh2::CellBounds& bounds, uint32_t count,
                                     Consider consider, uint32_t* left_count_out) {
    float cost[kLanes][3] = {};
    bool valid[kLanes][3] = {};
    uint32_t left_clusters[kLanes][3] = {};
    for (int axis = 0; axis < 3; ++axis) {
        TopBin below[kLanes], above[kLanes];
        for (uint32_t lane = 0; lane < kLanes; ++lane) below[lane] = above[lane] = bins[lane][axis];
        for (uint32_t d = 1; d < kLanes; d *= 2) {  // __shfl_up_sync / __shfl_down_sync scans
            TopBin next_below[kLanes], next_above[kLanes];
            for (uint32_t lane = 0; lane < kLanes; ++lane) {
                next_below[lane] = lane >= d ? hlbvh2::merge_bins(below[lane - d], below[lane]) : below[lane];
                next_above[lane] = lane + d < kLanes ? hlbvh2::merge_bins(above[lane], above[lane + d]) : above[lane];
            }
            std::copy(next_below, next_below + kLanes, below);
            std::copy(next_above, next_above + kLanes, above);
        }
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const TopBin left = lane == 0 ? TopBin{} : below[lane - 1];
            valid[lane][axis] = lane >= 1 && lane < hlbvh2::axis_bins(bounds, axis) &&
                                hlbvh2::plane_cost(left, above[lane], &cost[lane][axis]);
            left_clusters[lane][axis] = left.clusters;
        }
    }
    hlbvh2::TopSplit split;  // every lane folds the same candidates: lane 0's fold stands for all
    uint32_t left_count = count / 2;
    for (int axis = 0; axis < 3; ++axis) {
        for (uint32_t plane = 1; plane < kLanes; ++plane) {
            if (valid[plane][axis] && consider(split, cost[plane][axis], axis, plane)) {
                left_count = left_clusters[plane][axis];
            }
        }
    }
    *left_count_out = left_count;
    return split;
}

// process_top_task of hlbvh2_top_level.cu, its 8 lanes in lockstep: each
// shuffle reads the other lanes' values from before the step.
uint32_t emulate_top_task(const TopTask& task, const TopCluster* in, TopCluster* out, uint32_t top_base,
                          uint32_t* top_refs, TopTask children[2], Consider consider) {
    const uint32_t count = task.end - task.first;
    hlbvh2::CellBounds bounds[kLanes];
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        bounds[lane] = hlbvh2::strided_cell_bounds(in, task.first, task.end, lane, kLanes);
    }
    for (uint32_t d = kLanes / 2; d > 0; d /= 2) {  // __shfl_xor_sync butterfly
        hlbvh2::CellBounds next[kLanes];
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            next[lane] = bounds[lane];
            hlbvh2::merge(next[lane], bounds[lane ^ d]);
        }
        std::copy(next, next + kLanes, bounds);
    }
    TopBin bins[kLanes][3];
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        hlbvh2::bin_task_lane(in, task.first, task.end, bounds[lane], lane, bins[lane]);
    }
    uint32_t left_count = 0;
    const hlbvh2::TopSplit split = emulate_split_lanes(bins, bounds[0], count, consider, &left_count);
    const uint32_t right_count = count - left_count;
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kLanes) {
        bool left[kLanes] = {};
        uint32_t left_bits = 0;  // the ballot
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const uint32_t i = chunk + lane;
            if (i >= task.end) continue;
            left[lane] = hlbvh2::cluster_goes_left(in[i], i, task, bounds[lane], split, left_count);
            left_bits |= (left[lane] ? 1u : 0u) << lane;
        }
        for (uint32_t lane = 0; lane < kLanes; ++lane) {
            const uint32_t i = chunk + lane;
            if (i >= task.end) continue;
            const uint32_t lefts_before = lefts + static_cast<uint32_t>(std::popcount(left_bits & ((1u << lane) - 1u)));
            out[hlbvh2::partition_slot(task, left_count, i, lefts_before, left[lane])] = in[i];
            if (left[lane] && left_count == 1) top_refs[2 * task.node] = in[i].root;
            if (!left[lane] && right_count == 1) top_refs[2 * task.node + 1] = in[i].root;
        }
        lefts += static_cast<uint32_t>(std::popcount(left_bits));
    }
    TopTask halves[2];
    hlbvh2::child_tasks(task, left_count, halves);
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first < 2) continue;
        top_refs[2 * task.node + side] = top_base + halves[side].node;
        children[inner++] = halves[side];
    }
    return inner;
}

// The block path (top_large_task_kernel) emulated: shared-memory atomics as
// plain updates (they commute: any order gives the same words).
constexpr uint32_t kTaskBlock = 256;  // hlbvh2_top_level.cu's kTopTaskBlock
constexpr uint32_t kTaskBlockWarps = kTaskBlock / kWarp;
struct PlainAtomics {
    void min(uint32_t* word, uint32_t value) const { *word = std::min(*word, value); }
    void max(uint32_t* word, uint32_t value) const { *word = std::max(*word, value); }
    void add(uint32_t* word, uint32_t value) const { *word += value; }
};

// Equal as values: zeros of either sign are equal (the only difference the
// key encoding may make, see hlbvh2_top_steps.h).
bool same_bin_value(const TopBin& a, const TopBin& b) {
    return a.box.lo.x == b.box.lo.x && a.box.lo.y == b.box.lo.y && a.box.lo.z == b.box.lo.z &&
           a.box.hi.x == b.box.hi.x && a.box.hi.y == b.box.hi.y && a.box.hi.z == b.box.hi.z &&
           a.triangles == b.triangles && a.clusters == b.clusters;
}

struct BlockPathStats {
    size_t tasks = 0;           // tasks run by the block path
    size_t bin_mismatches = 0;  // merged shared bins unlike bin_task's
    size_t bad_slots = 0;       // partition slots outside the task (skipped: a bug's symptom)
    size_t zero_signs = 0;      // bins equal to bin_task's as values, not as bits
};

// top_large_task_kernel for one task, its threads in shuffled orders:
// strided cell bounds merged as the shared atomics would, strided binning
// into the warps' key bins, the 8 lanes' merge and split, the partition by
// an exclusive scan per chunk of kTaskBlock clusters. `stride`: the threads'
// stride over the clusters (kTaskBlock; anything else is a bug to catch).
uint32_t emulate_large_top_task(const TopTask& task, const TopCluster* in, TopCluster* out, uint32_t top_base,
                                uint32_t* top_refs, TopTask children[2], Consider consider, uint32_t stride,
                                std::mt19937& rng, BlockPathStats& stats) {
    const uint32_t count = task.end - task.first;
    std::vector<uint32_t> threads(kTaskBlock);
    std::iota(threads.begin(), threads.end(), 0u);
    std::shuffle(threads.begin(), threads.end(), rng);
    hlbvh2::CellBounds bounds = hlbvh2::empty_cell_bounds();
    for (uint32_t t : threads) hlbvh2::merge(bounds, hlbvh2::strided_cell_bounds(in, task.first, task.end, t, stride));
    std::shuffle(threads.begin(), threads.end(), rng);
    hlbvh2::TopBinKeys warp_bins[kTaskBlockWarps][3][hlbvh2::kTopBins];
    for (auto& warp : warp_bins) {
        for (auto& axis : warp) std::fill(axis, axis + hlbvh2::kTopBins, hlbvh2::empty_bin_keys());
    }
    PlainAtomics atomics;
    for (uint32_t t : threads) {
        hlbvh2::strided_bin_keys(in, task.first, task.end, t, stride, bounds, warp_bins[t / kWarp], atomics);
    }
    TopBin bins[kLanes][3];
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        for (int axis = 0; axis < 3; ++axis) {
            hlbvh2::TopBinKeys keys = warp_bins[0][axis][lane];
            for (uint32_t w = 1; w < kTaskBlockWarps; ++w) hlbvh2::merge_keys(keys, warp_bins[w][axis][lane]);
            bins[lane][axis] = hlbvh2::decode_bin(keys);
        }
    }
    TopBin expected[3][hlbvh2::kTopBins];
    hlbvh2::bin_task(in, task.first, task.end, bounds, expected);
    for (uint32_t lane = 0; lane < kLanes; ++lane) {
        for (int axis = 0; axis < 3; ++axis) {
            const bool same = same_bin_value(bins[lane][axis], expected[axis][lane]);
            stats.bin_mismatches += !same;
            stats.zero_signs += same && !same_box(bins[lane][axis].box, expected[axis][lane].box);
        }
    }
    ++stats.tasks;
    uint32_t left_count = 0;
    const hlbvh2::TopSplit split = emulate_split_lanes(bins, bounds, count, consider, &left_count);
    const uint32_t right_count = count - left_count;
    uint32_t lefts = 0;
    for (uint32_t chunk = task.first; chunk < task.end; chunk += kTaskBlock) {
        bool left[kTaskBlock] = {};
        uint32_t before[kTaskBlock] = {};  // cub::BlockScan's exclusive sum, in thread order
        uint32_t chunk_lefts = 0;
        for (uint32_t t = 0; t < kTaskBlock; ++t) {
            const uint32_t i = chunk + t;
            left[t] = i < task.end && hlbvh2::cluster_goes_left(in[i], i, task, bounds, split, left_count);
            before[t] = chunk_lefts;
            chunk_lefts += left[t] ? 1u : 0u;
        }
        std::shuffle(threads.begin(), threads.end(), rng);
        for (uint32_t t : threads) {
            const uint32_t i = chunk + t;
            if (i >= task.end) continue;
            const uint32_t slot = hlbvh2::partition_slot(task, left_count, i, lefts + before[t], left[t]);
            if (slot < task.first || slot >= task.end) {
                ++stats.bad_slots;
                continue;
            }
            out[slot] = in[i];
            if (left[t] && left_count == 1) top_refs[2 * task.node] = in[i].root;
            if (!left[t] && right_count == 1) top_refs[2 * task.node + 1] = in[i].root;
        }
        lefts += chunk_lefts;
    }
    TopTask halves[2];
    hlbvh2::child_tasks(task, left_count, halves);
    uint32_t inner = 0;
    for (int side = 0; side < 2; ++side) {
        if (halves[side].end - halves[side].first < 2) continue;
        top_refs[2 * task.node + side] = top_base + halves[side].node;
        children[inner++] = halves[side];
    }
    return inner;
}

struct QueueTop {
    std::vector<uint32_t> refs;                       // 2 per top node
    std::vector<std::vector<uint32_t>> level_nodes;   // per level, the task's node numbers
    BlockPathStats block;                             // the block path's share
};

// How the emulation splits the levels: tasks of more than block_min
// clusters take the block path (the device's kTopBlockTaskMin; lower values
// send more tasks through it), whose threads stride by block_stride.
struct TopSchedule {
    uint32_t block_min = hlbvh2::kTopBlockTaskMin;
    uint32_t block_stride = kTaskBlock;
};

// The task-queue launches of hlbvh2_top_level.cu: per level, the large
// tasks' blocks in a shuffled order, then the small tasks' warps in a
// shuffled order; two queues (small, large) ping-pong.
QueueTop run_top_task_queues(std::vector<TopCluster> clusters, uint32_t top_base, uint32_t seed,
                             Consider consider = hlbvh2::consider, TopSchedule schedule = {}) {
    const uint32_t count = static_cast<uint32_t>(clusters.size());
    QueueTop top;
    if (count < 2) return top;
    top.refs.assign(2 * size_t{count - 1}, kUnset);
    std::vector<TopCluster> buffer[2] = {std::move(clusters), std::vector<TopCluster>(count)};
    const bool root_is_large = count > schedule.block_min;
    std::vector<TopTask> queue[2], large_queue[2];
    (root_is_large ? large_queue[0] : queue[0]).push_back(TopTask{0, count, 0});
    const size_t large_capacity = std::max(1u, count / (schedule.block_min + 1));
    std::mt19937 rng(seed);
    int side = 0;
    while (!queue[side].empty() || !large_queue[side].empty()) {
        const std::vector<TopTask>& input = queue[side];
        const std::vector<TopTask>& large_input = large_queue[side];
        std::vector<TopTask>& output = queue[1 - side];
        std::vector<TopTask>& large_output = large_queue[1 - side];
        output.assign(count / 2, TopTask{kUnset, kUnset, kUnset});
        large_output.clear();
        uint32_t tail = 0;
        std::vector<uint32_t> nodes(large_input.size() + input.size(), kUnset);  // large tasks' first
        std::vector<uint32_t> blocks(large_input.size());
        std::iota(blocks.begin(), blocks.end(), 0u);
        std::shuffle(blocks.begin(), blocks.end(), rng);
        for (uint32_t block : blocks) {
            TopTask children[2];
            const uint32_t inner = emulate_large_top_task(large_input[block], buffer[side].data(),
                                                          buffer[1 - side].data(), top_base, top.refs.data(),
                                                          children, consider, schedule.block_stride, rng, top.block);
            nodes[block] = large_input[block].node;
            for (uint32_t k = 0; k < inner; ++k) {
                if (children[k].end - children[k].first > schedule.block_min) {
                    large_output.push_back(children[k]);
                } else {
                    output[tail++] = children[k];
                }
            }
        }
        EXPECT_LE(large_output.size(), large_capacity);
        std::vector<uint32_t> warps((input.size() + kTasksPerWarp - 1) / kTasksPerWarp);
        std::iota(warps.begin(), warps.end(), 0u);
        std::shuffle(warps.begin(), warps.end(), rng);
        for (uint32_t warp : warps) {
            TopTask children[kTasksPerWarp][2];
            uint32_t inner[kTasksPerWarp] = {};
            uint32_t one_or_more = 0, two = 0;  // ballots of the tasks' lane 0s
            for (uint32_t group = 0; group < kTasksPerWarp; ++group) {
                const size_t at = size_t{warp} * kTasksPerWarp + group;
                if (at >= input.size()) continue;
                EXPECT_LE(input[at].end - input[at].first, schedule.block_min) << "a large task in the small queue";
                inner[group] = emulate_top_task(input[at], buffer[side].data(), buffer[1 - side].data(), top_base,
                                                top.refs.data(), children[group], consider);
                nodes[large_input.size() + at] = input[at].node;
                one_or_more |= (inner[group] >= 1 ? 1u : 0u) << (group * kLanes);
                two |= (inner[group] == 2 ? 1u : 0u) << (group * kLanes);
            }
            const uint32_t base = tail;
            tail += hlbvh2::enqueue_total(one_or_more, two);
            for (uint32_t group = 0; group < kTasksPerWarp; ++group) {
                const uint32_t offset = base + hlbvh2::enqueue_offset(one_or_more, two, static_cast<int>(group * kLanes));
                for (uint32_t k = 0; k < inner[group]; ++k) output[offset + k] = children[group][k];
            }
        }
        output.resize(tail);
        top.level_nodes.push_back(std::move(nodes));
        queue[side].clear();
        large_queue[side].clear();
        side = 1 - side;
    }
    return top;
}

// The clusters as the device's top level sees them, after the bottom levels.
std::vector<TopCluster> top_clusters(const SortedClusters& s, const QueueForest& f, std::vector<Box3f>& inner_boxes) {
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    inner_boxes.assign(n > 0 ? n - 1 : 0, Box3f{});
    const hlbvh2::BoxView view{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                               inner_boxes.data()};
    for (size_t l = f.level_nodes.size(); l-- > 0;) {
        for (uint32_t node : f.level_nodes[l]) {
            if (node != hlbvh2::kNoNode) hlbvh2::node_box(view, node);
        }
    }
    std::vector<TopCluster> clusters;
    for (size_t c = 0; c < s.cluster_prefix.size(); ++c) {
        const uint32_t root = f.refs[2 * (n - 1) + c];
        clusters.push_back({hlbvh2::reference_box(view, root), hlbvh2::pack_cells(s.cluster_prefix[c]),
                            s.cluster_begin[c + 1] - s.cluster_begin[c], root});
    }
    return clusters;
}

std::vector<NamedScene> top_scenes() {
    std::vector<NamedScene> out = scenes();
    out.push_back({"big soup", test::make_triangle_soup(40000, 2, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.05f)});
    SceneGeometry plane;  // every centroid at z = 0: every cluster in one cell-plane
    for (int x = 0; x < 40; ++x) {
        for (int y = 0; y < 40; ++y) {
            const Vec3f p{static_cast<float>(x), static_cast<float>(y) * 0.7f, 0.0f};
            test::append(plane, {p, p + Vec3f(0.3f, 0, 0), p + Vec3f(0, 0.3f, 0)});
        }
    }
    out.push_back({"one cell-plane", std::move(plane)});
    SceneGeometry lattice;  // 8^3 equal triangles on a cubic lattice: equal costs on every axis
    for (int x = 0; x < 8; ++x) {
        for (int y = 0; y < 8; ++y) {
            for (int z = 0; z < 8; ++z) {
                const Vec3f p{static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
                test::append(lattice, {p - Vec3f(0.1f), p + Vec3f(0.1f, 0.1f, -0.1f), p + Vec3f(-0.1f, 0.1f, 0.1f)});
            }
        }
    }
    out.push_back({"equal costs", std::move(lattice)});
    return out;
}

// Random distinct cells with random boxes, as the top level's only input.
std::vector<TopCluster> random_clusters(uint32_t count, uint32_t seed, float extent) {
    std::mt19937 rng(seed);
    std::vector<uint32_t> prefixes(1u << 15);
    std::iota(prefixes.begin(), prefixes.end(), 0u);
    std::shuffle(prefixes.begin(), prefixes.end(), rng);
    prefixes.resize(count);
    std::sort(prefixes.begin(), prefixes.end());
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<TopCluster> clusters;
    for (uint32_t c = 0; c < count; ++c) {
        TopCluster cl;
        const uint32_t cells = hlbvh2::pack_cells(prefixes[c]);
        const Vec3f lo{(hlbvh2::cell_of(cells, 0) + unit(rng) * 0.5f) * extent,
                       (hlbvh2::cell_of(cells, 1) + unit(rng) * 0.5f) * extent,
                       (hlbvh2::cell_of(cells, 2) + unit(rng) * 0.5f) * extent};
        cl.box.lo = lo;
        cl.box.hi = lo + Vec3f(unit(rng), unit(rng), unit(rng)) * extent;
        cl.cells = cells;
        cl.triangles = 1 + rng() % 50;
        cl.root = kLeafRef | (c * 64);
        clusters.push_back(cl);
    }
    return clusters;
}

TEST(Hlbvh2DeviceLogic, TopLevelTaskQueuesBuildTheCpuTopLevel) {
    for (const NamedScene& scene : top_scenes()) {
        for (uint32_t leaf_size : {1u, 4u}) {
            SCOPED_TRACE(scene.name + ", leaves of " + std::to_string(leaf_size));
            const SortedClusters s = sort_and_cluster(scene.geometry.triangles);
            if (s.keys.size() < 2) continue;
            const uint32_t n = static_cast<uint32_t>(s.keys.size());
            const QueueForest f = run_work_queues(s, leaf_size, 5);
            std::vector<Box3f> inner_boxes;
            const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
            if (scene.name == "one point") EXPECT_EQ(clusters.size(), 1u);
            if (scene.name == "two") EXPECT_EQ(clusters.size(), 2u);
            if (scene.name == "one cell-plane") {
                EXPECT_GT(clusters.size(), 8u);
                for (const TopCluster& c : clusters) EXPECT_EQ(hlbvh2::cell_of(c.cells, 2), hlbvh2::cell_of(clusters[0].cells, 2));
            }
            std::vector<TopCluster> cpu_clusters = clusters;
            const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu_clusters, n - 1);
            ASSERT_EQ(expected.size(), clusters.size() > 1 ? 2 * (clusters.size() - 1) : 0u);
            // Two warp schedules (the second seed depends on the leaf size: four in all).
            // With leaves of 1, a third sends every task of 3 or more clusters through the block path.
            QueueTop top;
            for (uint32_t seed : {1u, 2u + leaf_size, 7u}) {
                if (seed == 7u && leaf_size != 1) continue;
                const TopSchedule schedule{.block_min = seed == 7u ? 2u : hlbvh2::kTopBlockTaskMin};
                top = run_top_task_queues(clusters, n - 1, seed, hlbvh2::consider, schedule);
                EXPECT_EQ(top.refs, expected);
                EXPECT_EQ(top.block.bin_mismatches, 0u);
                EXPECT_EQ(top.block.bad_slots, 0u);
                if (clusters.size() > schedule.block_min) EXPECT_GT(top.block.tasks, 0u);
                size_t nodes = 0;
                for (const auto& level : top.level_nodes) nodes += level.size();
                EXPECT_EQ(nodes, clusters.size() > 1 ? clusters.size() - 1 : 0u) << "every task is one top node";
            }
            const BvhBuildConfig config{.max_leaf_size = static_cast<int>(leaf_size)};
            EXPECT_TRUE(same_bvh(build_hlbvh2(scene.geometry.triangles, config),
                                 emit_hlbvh2_forest(scene.geometry.triangles, config, to_forest(s, f, top.refs))));
        }
    }
}

TEST(Hlbvh2DeviceLogic, TopLevelOfRandomAndExtremeClusters) {
    // Random cells; tiny and huge boxes (areas overflowing to inf and NaN
    // costs follow the same tie rules on both sides); equal boxes (all ties).
    for (uint32_t count : {2u, 3u, 9u, 100u, 1000u, 5000u}) {
        for (float extent : {1e-30f, 1.0f, 1e18f, 1e37f, 3e37f}) {
            SCOPED_TRACE(std::to_string(count) + " clusters, extent " + std::to_string(extent));
            std::vector<TopCluster> clusters = random_clusters(count, count + 17, extent);
            std::vector<TopCluster> cpu = clusters;
            const uint32_t top_base = 64 * count;
            EXPECT_EQ(run_top_task_queues(clusters, top_base, count).refs, build_hlbvh2_top_level(cpu, top_base));
            const QueueTop blocks = run_top_task_queues(clusters, top_base, count, hlbvh2::consider, {.block_min = 2});
            EXPECT_EQ(blocks.refs, build_hlbvh2_top_level(cpu, top_base)) << "block path only";
            EXPECT_EQ(blocks.block.bin_mismatches, 0u);
            for (TopCluster& c : clusters) {
                c.box = clusters[0].box;
                c.triangles = 3;
            }
            cpu = clusters;
            EXPECT_EQ(run_top_task_queues(clusters, top_base, count + 1).refs, build_hlbvh2_top_level(cpu, top_base));
        }
    }
}

TEST(Hlbvh2DeviceLogic, TopLevelBlockPathIgnoresSignsOfZero) {
    // Flat clusters whose z bounds are zeros of mixed signs: the key bins'
    // min / max may pick another zero than the CPU's unions (-0 orders below
    // +0 there), which must change no cost and no choice.
    for (uint32_t count : {300u, 3000u}) {
        std::vector<TopCluster> clusters = random_clusters(count, count + 5, 1.0f);
        for (uint32_t c = 0; c < count; ++c) {
            clusters[c].box.lo.z = c % 2 != 0 ? -0.0f : 0.0f;
            clusters[c].box.hi.z = c % 3 != 0 ? 0.0f : -0.0f;
            if (c % 5 == 0) clusters[c].box.lo.x = clusters[c].box.hi.x = c % 10 == 0 ? -0.0f : 0.0f;
        }
        std::vector<TopCluster> cpu = clusters;
        const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, 64 * count);
        for (uint32_t block_min : {2u, hlbvh2::kTopBlockTaskMin}) {
            const QueueTop top = run_top_task_queues(clusters, 64 * count, block_min, hlbvh2::consider, {.block_min = block_min});
            EXPECT_EQ(top.refs, expected);
            EXPECT_EQ(top.block.bin_mismatches, 0u);
            EXPECT_GT(top.block.tasks, 0u);
            if (block_min == 2) EXPECT_GT(top.block.zero_signs, 0u) << "no zero of another sign was met";
        }
    }
}

// A soup spread over the whole grid: thousands of occupied 15-bit cells, so
// the first levels' tasks (up to ~30,000 clusters) take the block path.
struct SpreadSoup {
    SceneGeometry geometry;
    SortedClusters sorted;
    QueueForest forest;
    std::vector<TopCluster> clusters;
};
const SpreadSoup& spread_soup() {
    static const SpreadSoup soup = [] {
        SpreadSoup s;
        s.geometry = test::make_triangle_soup(60000, 11, {Vec3f(-20.0f), Vec3f(20.0f)}, 0.1f);
        s.sorted = sort_and_cluster(s.geometry.triangles);
        s.forest = run_work_queues(s.sorted, 4, 3);
        std::vector<Box3f> inner_boxes;
        s.clusters = top_clusters(s.sorted, s.forest, inner_boxes);
        return s;
    }();
    return soup;
}

TEST(Hlbvh2DeviceLogic, TopLevelBlockPathOnASpreadSoup) {
    const SpreadSoup& soup = spread_soup();
    ASSERT_GE(soup.clusters.size(), 5000u);
    const uint32_t n = static_cast<uint32_t>(soup.sorted.keys.size());
    std::vector<TopCluster> cpu = soup.clusters;
    const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, n - 1);
    QueueTop top;
    for (uint32_t seed : {1u, 2u, 3u}) {
        top = run_top_task_queues(soup.clusters, n - 1, seed);
        EXPECT_EQ(top.refs, expected);
        EXPECT_EQ(top.block.bin_mismatches, 0u);
        EXPECT_EQ(top.block.bad_slots, 0u);
        EXPECT_GE(top.block.tasks, soup.clusters.size() / (2 * hlbvh2::kTopBlockTaskMin)) << "the block path ran";
        EXPECT_EQ(top.level_nodes[0].size(), 1u);
    }
    const BvhBuildConfig config{.max_leaf_size = 4};
    EXPECT_TRUE(same_bvh(build_hlbvh2(soup.geometry.triangles, config),
                         emit_hlbvh2_forest(soup.geometry.triangles, config, to_forest(soup.sorted, soup.forest, top.refs))));
}

TEST(Hlbvh2DeviceLogic, WrongBlockStrideIsCaught) {
    const SpreadSoup& soup = spread_soup();
    const uint32_t n = static_cast<uint32_t>(soup.sorted.keys.size());
    std::vector<TopCluster> cpu = soup.clusters;
    const std::vector<uint32_t> expected = build_hlbvh2_top_level(cpu, n - 1);
    // One too few: some clusters binned twice; one too many: some never.
    for (uint32_t stride : {kTaskBlock - 1, kTaskBlock + 1}) {
        SCOPED_TRACE("stride " + std::to_string(stride));
        const QueueTop wrong = run_top_task_queues(soup.clusters, n - 1, 1, hlbvh2::consider, {.block_stride = stride});
        EXPECT_GT(wrong.block.bin_mismatches, 0u);
        EXPECT_NE(wrong.refs, expected);
    }
}

TEST(Hlbvh2DeviceLogic, TopLevelBoxesAreUnionsOfClusters) {
    const SortedClusters s = sort_and_cluster(test::make_triangle_soup(20000, 8, {Vec3f(-5.0f), Vec3f(5.0f)}, 0.2f).triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const QueueForest f = run_work_queues(s, 4, 2);
    std::vector<Box3f> inner_boxes;
    const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
    ASSERT_GT(clusters.size(), 100u);
    const QueueTop top = run_top_task_queues(clusters, n - 1, 4);
    std::vector<Box3f> top_boxes(clusters.size() - 1);
    const hlbvh2::TopBoxView view{{f.refs.data(), f.leaf_runs.data(), s.order.data(), s.triangle_boxes.data(),
                                   inner_boxes.data()},
                                  top.refs.data(), n - 1, top_boxes.data()};
    for (size_t l = top.level_nodes.size(); l-- > 0;) {  // deepest level first, one launch each
        for (uint32_t k : top.level_nodes[l]) hlbvh2::top_node_box(view, k);
    }
    // The root's box is the union of every cluster's; every box holds its children's.
    Box3f all = clusters[0].box;
    for (const TopCluster& c : clusters) all = hlbvh2::box_union(all, c.box);
    EXPECT_TRUE(same_box(top_boxes[0], all));
    size_t wrong = 0;
    for (size_t k = 0; k < top_boxes.size(); ++k) {
        for (int side = 0; side < 2; ++side) {
            const Box3f child = hlbvh2::top_reference_box(view, top.refs[2 * k + side]);
            wrong += !same_box(hlbvh2::box_union(top_boxes[k], child), top_boxes[k]);
        }
    }
    EXPECT_EQ(wrong, 0u);
}

TEST(Hlbvh2DeviceLogic, WrongTopTieRuleIsCaught) {
    const std::vector<NamedScene> all = top_scenes();
    const SceneGeometry& g = all.back().geometry;  // equal costs
    const SortedClusters s = sort_and_cluster(g.triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const QueueForest f = run_work_queues(s, 1, 1);
    std::vector<Box3f> inner_boxes;
    const std::vector<TopCluster> clusters = top_clusters(s, f, inner_boxes);
    std::vector<TopCluster> cpu = clusters;
    const QueueTop wrong = run_top_task_queues(clusters, n - 1, 1, consider_last_of_equals);
    EXPECT_NE(wrong.refs, build_hlbvh2_top_level(cpu, n - 1));
    const BvhBuildConfig config{.max_leaf_size = 1};
    EXPECT_FALSE(same_bvh(build_hlbvh2(g.triangles, config),
                          emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, wrong.refs))));
}

TEST(Hlbvh2DeviceLogic, MalformedTopLevelThrows) {
    const SceneGeometry g = test::make_triangle_soup(2000, 4, {Vec3f(-1.0f), Vec3f(1.0f)}, 0.2f);
    const SortedClusters s = sort_and_cluster(g.triangles);
    const uint32_t n = static_cast<uint32_t>(s.keys.size());
    const QueueForest f = run_work_queues(s, 1, 1);
    std::vector<Box3f> inner_boxes;
    const std::vector<uint32_t> good = run_top_task_queues(top_clusters(s, f, inner_boxes), n - 1, 1).refs;
    ASSERT_GT(good.size(), 4u);
    const BvhBuildConfig config{.max_leaf_size = 1};
    EXPECT_NO_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, good)));
    std::vector<uint32_t> bad = good;
    bad[2] = n - 1;  // a child replaced by the root: a cycle
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
    bad = good;
    bad.back() = bad.front();  // a reference used twice
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
    bad = good;
    bad.pop_back();
    EXPECT_THROW((void)emit_hlbvh2_forest(g.triangles, config, to_forest(s, f, bad)), Error);
}

}  // namespace
}  // namespace rf
