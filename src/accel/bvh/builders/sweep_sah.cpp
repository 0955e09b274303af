// Full sweep SAH builder (the exact top-down SAH evaluation of MacDonald and
// Booth 1990, "Heuristics for ray tracing using space subdivision", as used
// for BVHs by Wald, Boulos and Shirley 2007, "Ray tracing deformable scenes
// using dynamic bounding volume hierarchies").
//
// The primitive ids are sorted once per axis by centroid (ties broken by id,
// so the order is total). A node owns the same range [begin, end) of all three
// sorted lists; a sweep over each list evaluates the SAH at every split
// position, and the chosen split partitions the other two lists stably, so
// they stay sorted: O(N log N) for the sort plus O(N) per tree level. Leaves
// name ranges of the x-sorted list, which are already in depth-first order.
// From the top-down skeleton (top_down_sah.h) it takes the recursion, the
// leaf decision and its fallbacks (halving along the widest centroid axis
// where the depth limit is near), the node allocation, subtree tasks and the
// depth-first copy; this file sweeps and partitions.
//
// Parallelism (TBB via core/parallel.h): the three initial sorts run at once,
// each a parallel merge sort; large nodes sweep and partition their three axes
// as separate tasks; the skeleton builds subtrees above a size threshold as
// separate tasks. Every decision depends only on the node's primitives, so
// the output is the same for every thread count.
#include "accel/bvh/builders/sweep_sah.h"

#include <algorithm>
#include <cstdint>
#include <vector>

#include "accel/bvh/builders/sweep_common.h"
#include "accel/bvh/builders/top_down_sah.h"
#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using sweep::grow;

constexpr uint32_t kParallelAxesSize = 8 * 1024;      // prims per node to sweep the axes as tasks
constexpr uint32_t kGrainSize = 16 * 1024;

struct AxisSplit {
    float cost = kInfinity;  // sum of area * count over both children
    uint32_t position = 0;   // references [begin, begin + position) of the sorted list go left
    [[nodiscard]] bool valid() const { return position != 0; }
};

// The skeleton's view of a node: its range of the sorted lists and its box.
struct SweepTask {
    uint32_t begin = 0, end = 0;
    Box3f box;
    [[nodiscard]] uint32_t count() const { return end - begin; }
    [[nodiscard]] const Box3f& bounds() const { return box; }
};

// The cheapest split over the three sorted lists.
struct SweepSplit {
    int axis = 0;
    AxisSplit best;
    [[nodiscard]] bool valid() const { return best.valid(); }
    [[nodiscard]] float cost() const { return best.cost; }
    [[nodiscard]] uint32_t larger_child(uint32_t count) const {
        return std::max(best.position, count - best.position);
    }
};

class SweepSahBuilder : public top_down::TopDownSahBuilder<SweepSahBuilder, SweepTask> {
public:
    SweepSahBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config)
        : TopDownSahBuilder(config), triangles_(triangles) {}

    Bvh build() {
        const uint32_t count = checked_index_count("BVH primitive count", triangles_.size());
        if (count == 0) return Bvh{};
        budgeted_resize(boxes_, count, "sweep SAH build: primitive boxes");
        SweepTask root{0, count, make_boxes(count)};
        sort_axes(count);
        for (auto& a : right_area_) budgeted_resize(a, count, "sweep SAH build: sweep areas");
        for (auto& t : temp_) budgeted_resize(t, count, "sweep SAH build: partition buffer");
        budgeted_resize(goes_left_, count, "sweep SAH build: partition flags");
        return build_tree(root, count);
    }

private:
    friend TopDownSahBuilder;
    static constexpr const char* kName = "sweep SAH build";
    static constexpr uint32_t kParallelSubtreeSize = 1024;  // prims per node to spawn child tasks
    static constexpr bool kLeavesInPlace = true;

    Box3f make_boxes(uint32_t count) {
        return parallel::reduce(
            0u, count, kGrainSize, Box3f{},
            [&](uint32_t lo, uint32_t hi, Box3f acc) {
                for (uint32_t i = lo; i != hi; ++i) {
                    const Triangle& t = triangles_[i];
                    boxes_[i] = Box3f{sweep::vmin(t.v0, sweep::vmin(t.v1, t.v2)),
                                      sweep::vmax(t.v0, sweep::vmax(t.v1, t.v2))};
                    grow(acc, boxes_[i]);
                }
                return acc;
            },
            [](Box3f a, const Box3f& b) { grow(a, b); return a; });
    }

    // order_[axis]: ids sorted by (centroid on axis, id).
    void sort_axes(uint32_t count) {
        auto sort_axis = [&](int axis) {
            std::vector<uint64_t> keys, tmp;
            budgeted_resize(keys, count, "sweep SAH build: sort keys");
            budgeted_resize(tmp, count, "sweep SAH build: sort buffer");
            parallel::for_range(0u, count, kGrainSize, [&](uint32_t lo, uint32_t hi) {
                for (uint32_t i = lo; i != hi; ++i) {
                    // Half sums cannot overflow where the plain sum of two large values would.
                    keys[i] = sweep::sort_key(0.5f * boxes_[i].lo[axis] + 0.5f * boxes_[i].hi[axis], i);
                }
            });
            sweep::parallel_sort(keys.data(), tmp.data(), count);
            budgeted_resize(order_[axis], count, "sweep SAH build: sorted lists");
            parallel::for_range(0u, count, kGrainSize, [&](uint32_t lo, uint32_t hi) {
                for (uint32_t i = lo; i != hi; ++i) order_[axis][i] = static_cast<uint32_t>(keys[i]);
            });
        };
        parallel::invoke([&] { sort_axis(0); }, [&] { parallel::invoke([&] { sort_axis(1); }, [&] { sort_axis(2); }); });
    }

    // Runs f(0), f(1), f(2), as tasks for large nodes.
    template <class F>
    void for_axes(uint32_t count, F&& f) {
        if (count >= kParallelAxesSize) {
            parallel::invoke([&] { f(0); }, [&] { parallel::invoke([&] { f(1); }, [&] { f(2); }); });
        } else {
            f(0);
            f(1);
            f(2);
        }
    }

    // ---- The skeleton's hooks.

    SweepSplit find_split(const SweepTask& task, int /*depth*/) {
        AxisSplit splits[3];
        for_axes(task.count(), [&](int axis) { splits[axis] = sweep_axis(axis, task.begin, task.end); });
        SweepSplit split;  // ties go to the lower axis: the same choice on every run
        for (int a = 1; a < 3; ++a) {
            if (splits[a].cost < splits[split.axis].cost) split.axis = a;
        }
        split.best = splits[split.axis];
        return split;
    }
    void partition(const SweepTask& task, const SweepSplit& split, SweepTask& left, SweepTask& right) {
        partition_lists(task, split.axis, task.begin + split.best.position, left, right);
    }
    // Halves along the widest centroid axis.
    void partition_at_median(const SweepTask& task, const SweepSplit& /*split*/, SweepTask& left, SweepTask& right) {
        const uint32_t mid = task.begin + task.count() / 2;
        partition_lists(task, widest_centroid_axis(task.begin, task.end), mid, left, right);
    }
    static uint32_t place_leaf(const SweepTask& task) { return task.begin; }
    [[nodiscard]] uint32_t slot_prim(uint32_t slot) const { return order_[0][slot]; }

    // The cheapest split of the sorted list of `axis` over [begin, end).
    AxisSplit sweep_axis(int axis, uint32_t begin, uint32_t end) {
        const uint32_t* ids = order_[axis].data();
        float* right_area = right_area_[axis].data();
        // Suffix sweep: right_area[i] is the area of the box of ids[i, end).
        Box3f acc;
        for (uint32_t i = end - 1; i > begin; --i) {
            grow(acc, boxes_[ids[i]]);
            right_area[i] = acc.surface_area();
        }
        // Prefix sweep: the split before position i.
        AxisSplit best;
        acc = Box3f{};
        for (uint32_t i = begin + 1; i < end; ++i) {
            grow(acc, boxes_[ids[i - 1]]);
            const float left = static_cast<float>(i - begin), right = static_cast<float>(end - i);
            const float cost = acc.surface_area() * left + right_area[i] * right;
            if (!best.valid() || cost < best.cost) best = AxisSplit{cost, i - begin};  // even when costs overflow
        }
        return best;
    }

    // The references before `mid` in the sorted list of `axis` go left:
    // flag them, then partition the other two lists stably.
    void partition_lists(const SweepTask& task, int axis, uint32_t mid, SweepTask& left, SweepTask& right) {
        const uint32_t* ids = order_[axis].data();
        left = SweepTask{task.begin, mid, Box3f{}};
        right = SweepTask{mid, task.end, Box3f{}};
        for (uint32_t i = task.begin; i < mid; ++i) {
            goes_left_[ids[i]] = 1;
            grow(left.box, boxes_[ids[i]]);
        }
        for (uint32_t i = mid; i < task.end; ++i) {
            goes_left_[ids[i]] = 0;
            grow(right.box, boxes_[ids[i]]);
        }
        for_axes(task.count(), [&](int a) {
            if (a != axis) stable_partition(a, task.begin, task.end, mid);
        });
    }

    // The sorted lists' ends give each axis' centroid extent for free.
    int widest_centroid_axis(uint32_t begin, uint32_t end) const {
        int best = 0;
        float best_extent = -1.0f;
        for (int a = 0; a < 3; ++a) {
            const Box3f& first = boxes_[order_[a][begin]];
            const Box3f& last = boxes_[order_[a][end - 1]];
            const float extent = (0.5f * last.lo[a] + 0.5f * last.hi[a]) - (0.5f * first.lo[a] + 0.5f * first.hi[a]);
            if (extent > best_extent) {
                best = a;
                best_extent = extent;
            }
        }
        return best;
    }

    void stable_partition(int axis, uint32_t begin, uint32_t end, uint32_t mid) {
        uint32_t* ids = order_[axis].data();
        uint32_t* tmp = temp_[axis].data();
        uint32_t left = begin, right = mid;
        for (uint32_t i = begin; i < end; ++i) {
            const uint32_t id = ids[i];
            tmp[goes_left_[id] ? left++ : right++] = id;
        }
        std::copy(tmp + begin, tmp + end, ids + begin);
    }

    std::span<const Triangle> triangles_;
    std::vector<Box3f> boxes_;               // per triangle
    std::vector<uint32_t> order_[3];         // ids sorted per axis; a node owns one range of each
    std::vector<float> right_area_[3];       // sweep scratch, per axis, indexed like order_
    std::vector<uint32_t> temp_[3];          // partition scratch, per axis
    std::vector<uint8_t> goes_left_;         // per triangle: side of the current split
};

}  // namespace

Bvh build_sweep_sah(std::span<const Triangle> triangles, const BvhBuildConfig& config) {
    SweepSahBuilder builder(triangles, config);
    return builder.build();
}

}  // namespace rf
