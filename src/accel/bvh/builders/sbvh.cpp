// SBVH builder (Stich, Friedrich and Dietrich 2009, "Spatial Splits in
// Bounding Volume Hierarchies").
//
// Top-down over references (a triangle id plus a box that holds the part of
// the triangle inside the node). Per node:
//  - object split: a full SAH sweep over the references sorted by box centre
//    on each axis;
//  - spatial split, tried only where the children of the best object split
//    overlap by more than SbvhOptions::alpha times the root's area: the
//    node's box is cut into slabs per axis (2 per reference, 8 to 32), every
//    reference is chopped into the slabs it spans (the triangle clipped
//    against the slab planes, so each piece has a tight box), and a sweep
//    over the slab boundaries evaluates the SAH with entry/exit counts;
//  - reference unsplitting (section 4.3): a straddling reference is kept whole
//    on one side where that is cheaper than splitting it.
// The best spatial candidate is applied (with unsplitting) and chosen where
// the SAH of the children it really produces, A_L N_L + A_R N_R, is below the
// best object split's: the binned estimate counts every straddling reference
// on both sides, and unsplitting often makes a candidate that looked worse
// the cheaper split.
// From the top-down skeleton (top_down_sah.h) it takes the recursion, the
// leaf decision by SAH within max_leaf_size and its fallbacks (the object
// median where the depth limit is near), the node allocation, subtree tasks
// and the depth-first copy, which renumbers the leaf slots; this file finds
// and applies the splits and places the leaves.
// Memory stays bounded by a reference budget: at most kReferenceBudget (2)
// times the triangle count. A node gets a share of the spare references and
// hands what its split does not use to its children in proportion to their
// SAH weights (box area times references): subtrees of large triangles,
// where spatial splits pay off, get more than their count alone would give.
// Below the parallel subtree size children are built one after the other,
// and what the left subtree leaves unused goes on to the right one (the
// skeleton's carry). Neither depends on the order in which tasks run, so
// neither does the tree.
//
// Parallelism (TBB via core/parallel.h): the skeleton builds subtrees
// above a size threshold as tasks, and large nodes evaluate the three axes
// as tasks. Leaf slots come from a shared counter in task order; the
// depth-first copy renumbers them, so the output is the same for every
// thread count.
#include "accel/bvh/builders/sbvh.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include "accel/bvh/builders/sweep_common.h"
#include "accel/bvh/builders/top_down_sah.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using sweep::grow;

constexpr int kSpatialBins = 32;         // slabs per axis for large nodes
constexpr int kMinSpatialBins = 8;       // ... and small ones (2 per reference in between)
constexpr double kReferenceBudget = 2.0;          // references per triangle, at most
constexpr uint32_t kParallelAxesSize = 4 * 1024;  // refs per node to evaluate the axes as tasks
constexpr uint32_t kGrainSize = 16 * 1024;

struct Ref {
    Vec3f lo;
    uint32_t id;
    Vec3f hi;
    uint32_t unused = 0;
    [[nodiscard]] Box3f box() const { return {lo, hi}; }
    [[nodiscard]] float centre(int axis) const { return 0.5f * lo[axis] + 0.5f * hi[axis]; }
};

inline bool empty_box(const Box3f& b) { return b.lo.x > b.hi.x || b.lo.y > b.hi.y || b.lo.z > b.hi.z; }

inline Box3f intersect(const Box3f& a, const Box3f& b) {
    return {sweep::vmax(a.lo, b.lo), sweep::vmin(a.hi, b.hi)};
}

// The point of segment a-b at axis = pos (strictly between a[axis] and
// b[axis]; inv = 1 / (b[axis] - a[axis])), as a box widened on the other axes
// by a bound on its rounding error (a few ulps of the edge's coordinates), so
// a piece's box never loses a sliver of the triangle.
inline Box3f crossing(const Vec3f& a, const Vec3f& b, float inv, int axis, float pos) {
    const float t = std::clamp((pos - a[axis]) * inv, 0.0f, 1.0f);
    Vec3f lo = a + (b - a) * t, hi = lo;
    for (int k = 0; k < 3; ++k) {
        if (k == axis) {
            lo[k] = hi[k] = pos;
        } else {
            const float error = (std::fabs(a[k]) + std::fabs(b[k])) * 0x1p-21f;
            lo[k] -= error;
            hi[k] += error;
        }
    }
    return {lo, hi};
}

// Splits the part of `tri` inside `box` at axis = pos: `left` and `right` get
// the boxes of the two pieces, each clipped to `box` (so they stay inside the
// triangle's box), and empty where there is no piece.
void split_box(const Triangle& tri, const Box3f& box, int axis, float pos, Box3f& left, Box3f& right) {
    left = Box3f{};
    right = Box3f{};
    const Vec3f* v[3] = {&tri.v0, &tri.v1, &tri.v2};
    for (int e = 0; e < 3; ++e) {
        const Vec3f& p = *v[e];
        const Vec3f& q = *v[(e + 1) % 3];
        if (p[axis] <= pos) grow(left, p, p);
        if (p[axis] >= pos) grow(right, p, p);
        if ((p[axis] < pos && q[axis] > pos) || (p[axis] > pos && q[axis] < pos)) {
            const Box3f c = crossing(p, q, 1.0f / (q[axis] - p[axis]), axis, pos);
            grow(left, c);
            grow(right, c);
        }
    }
    left.hi[axis] = std::min(left.hi[axis], pos);
    right.lo[axis] = std::max(right.lo[axis], pos);
    left = intersect(left, box);
    right = intersect(right, box);
}

struct ObjectSplit {
    int axis = 0;
    uint32_t position = 0;  // refs at sorted positions [0, position) go left
    float cost = kInfinity;
    Box3f left, right;
};

struct SpatialSplit {
    int axis = -1;
    int plane = 0;  // slab boundary index in [1, bins)
    int bins = 0;
    float cost = kInfinity;
    uint32_t left_count = 0, right_count = 0;
    [[nodiscard]] bool valid() const { return axis >= 0; }
};

// Slab boundaries of a node's box along one axis. Bin lookups are corrected
// against the exact plane positions, so binning and splitting agree on every
// reference's side.
struct SlabMap {
    float lo = 0.0f, hi = 0.0f, extent = 0.0f, scale = 0.0f;
    int bins = 0;

    SlabMap(const Box3f& bounds, int axis, int bin_count)
        : lo(bounds.lo[axis]), hi(bounds.hi[axis]), extent(bounds.hi[axis] - bounds.lo[axis]), bins(bin_count) {
        const float s = static_cast<float>(bins) / extent;
        scale = (extent > 0.0f && std::isfinite(s)) ? s : 0.0f;
    }
    [[nodiscard]] bool usable() const { return scale > 0.0f; }
    // Plane 0 and plane `bins` are exactly the box's faces.
    [[nodiscard]] float plane(int k) const {
        if (k == bins) return hi;
        return lo + extent * (static_cast<float>(k) / static_cast<float>(bins));
    }
    // The slab b with plane(b) <= x < plane(b + 1), clamped to the valid range.
    [[nodiscard]] int bin(float x) const {
        float f = (x - lo) * scale;
        f = f > 0.0f ? f : 0.0f;
        f = f < static_cast<float>(bins - 1) ? f : static_cast<float>(bins - 1);
        int b = static_cast<int>(f);
        while (b > 0 && x < plane(b)) --b;
        while (b < bins - 1 && x >= plane(b + 1)) ++b;
        return b;
    }
};

// Grows bins[first..last] by the boxes of the pieces of `tri` inside `box`
// cut by the slab planes. Each slab's piece of the triangle is a convex
// polygon whose corners are the ends of the edge segments inside the slab, so
// one walk along each edge, crossing every plane once, gives all the pieces.
void chop_into_slabs(const Triangle& tri, const Box3f& box, int axis, const SlabMap& map, int first, int last,
                     Box3f* bins) {
    struct Piece {  // plain data: only the slabs in use get cleared
        Vec3f lo, hi;
    } pieces[kSpatialBins];
    for (int k = first; k <= last; ++k) pieces[k] = Piece{Vec3f(kInfinity), Vec3f(-kInfinity)};
    auto add = [&](int k, const Box3f& b) {
        pieces[k].lo = sweep::vmin(pieces[k].lo, b.lo);
        pieces[k].hi = sweep::vmax(pieces[k].hi, b.hi);
    };
    const Vec3f* v[3] = {&tri.v0, &tri.v1, &tri.v2};
    for (int e = 0; e < 3; ++e) {
        const Vec3f* a = v[e];
        const Vec3f* b = v[(e + 1) % 3];
        if ((*a)[axis] > (*b)[axis]) std::swap(a, b);
        const int from = std::max(map.bin((*a)[axis]), first);
        const int to = std::min(map.bin((*b)[axis]), last);
        if (from > to) continue;  // the edge misses the reference's slabs
        const float inv = 1.0f / ((*b)[axis] - (*a)[axis]);  // used only where a and b differ on the axis
        Box3f start = (*a)[axis] >= map.plane(from) ? Box3f{*a, *a} : crossing(*a, *b, inv, axis, map.plane(from));
        for (int k = from; k <= to; ++k) {
            const float end_pos = map.plane(k + 1);
            const Box3f end = (*b)[axis] <= end_pos ? Box3f{*b, *b} : crossing(*a, *b, inv, axis, end_pos);
            add(k, start);
            add(k, end);
            start = end;
        }
    }
    for (int k = first; k <= last; ++k) {
        const Box3f piece = intersect(Box3f{pieces[k].lo, pieces[k].hi}, box);
        if (!empty_box(piece)) grow(bins[k], piece);
    }
}

// Slabs per axis: chopping a reference costs one step per slab it spans, and
// in small nodes every reference spans most of them, so those get fewer.
inline int spatial_bins(size_t refs) {
    return static_cast<int>(std::clamp<size_t>(2 * refs, kMinSpatialBins, kSpatialBins));
}

// A reference's place in a node's order along one axis: by box centre, ties
// by triangle id (unique within a node, since the pieces of a split
// reference go to different children), so the order is total and the same
// as the sweep SAH builder's.
struct SortItem {
    uint64_t key;
    uint32_t index;  // into the node's references
    bool operator<(const SortItem& o) const { return key < o.key; }
};
struct SortedAxes {
    std::vector<SortItem> keys[3];
};

// The skeleton's view of a node: its references, its box and the spare
// references its subtree may add.
struct SbvhTask {
    std::vector<Ref> refs;
    Box3f box;
    uint64_t spare = 0;
    [[nodiscard]] uint32_t count() const { return static_cast<uint32_t>(refs.size()); }
    [[nodiscard]] const Box3f& bounds() const { return box; }
};

// A node's split: the best object split (with the node's sorted axes, which
// the object median reuses), or a spatial split already applied, with its
// children.
struct SbvhSplit {
    SortedAxes sorted;
    ObjectSplit object;
    bool spatial = false;
    uint32_t spatial_larger = 0;     // references of its larger side, as binned (at least as many as applied)
    float spatial_cost = kInfinity;  // A_L N_L + A_R N_R of its children as applied
    std::vector<Ref> left, right;
    Box3f left_box, right_box;
    // A node of two or more references always has an object split.
    [[nodiscard]] bool valid() const { return true; }
    [[nodiscard]] float cost() const { return spatial ? spatial_cost : object.cost; }
    [[nodiscard]] uint32_t larger_child(uint32_t count) const {
        return spatial ? spatial_larger : std::max(object.position, count - object.position);
    }
};

// The skeleton's carry: the spare references a finished subtree did not use.
using SpareRefs = uint64_t;

class SbvhBuilder : public top_down::TopDownSahBuilder<SbvhBuilder, SbvhTask, SpareRefs> {
public:
    SbvhBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const SbvhOptions& sbvh)
        : TopDownSahBuilder(config), triangles_(triangles), alpha_(sbvh.alpha) {}

    Bvh build() {
        const uint32_t count = checked_index_count("BVH primitive count", triangles_.size());
        if (count == 0) return Bvh{};
        const uint64_t max_refs = checked_index_count(
            "SBVH reference budget",
            std::max<uint64_t>(count, static_cast<uint64_t>(kReferenceBudget * static_cast<double>(count))));

        SbvhTask root;
        budgeted_resize(root.refs, count, "SBVH build: references");
        root.box = parallel::reduce(
            0u, count, kGrainSize, Box3f{},
            [&](uint32_t lo, uint32_t hi, Box3f acc) {
                for (uint32_t i = lo; i != hi; ++i) {
                    const Triangle& t = triangles_[i];
                    root.refs[i] = Ref{sweep::vmin(t.v0, sweep::vmin(t.v1, t.v2)), i,
                                       sweep::vmax(t.v0, sweep::vmax(t.v1, t.v2))};
                    grow(acc, root.refs[i].lo, root.refs[i].hi);
                }
                return acc;
            },
            [](Box3f a, const Box3f& b) { grow(a, b); return a; });
        root_area_ = root.box.surface_area();
        root.spare = max_refs - count;

        budgeted_resize(slots_, max_refs, "SBVH build: leaf slots");
        next_slot_.store(0, std::memory_order_relaxed);
        return build_tree(root, max_refs);
    }

private:
    friend TopDownSahBuilder;
    static constexpr const char* kName = "SBVH build";
    // Refs per node to spawn child tasks. Also part of the result: below it,
    // what a left subtree leaves of its spare references goes on to the right one.
    static constexpr uint32_t kParallelSubtreeSize = 512;
    static constexpr bool kLeavesInPlace = false;

    template <class F>
    static void for_axes(size_t count, F&& f) {
        if (count >= kParallelAxesSize) {
            parallel::invoke([&] { f(0); }, [&] { parallel::invoke([&] { f(1); }, [&] { f(2); }); });
        } else {
            f(0);
            f(1);
            f(2);
        }
    }

    // ---- The skeleton's hooks.

    // The best object split and, where a spatial split may pay off, the best
    // spatial candidate, applied (with reference unsplitting) and kept where
    // its cost after unsplitting is below the object split's, so both are
    // compared on the children they really produce.
    SbvhSplit find_split(const SbvhTask& task, int depth) const {
        SbvhSplit split;
        split.object = find_object_split(task.refs, split.sorted);
        if (task.spare > 0) try_spatial_split(task, depth, split);
        return split;
    }
    void partition(SbvhTask& task, SbvhSplit& split, SbvhTask& left, SbvhTask& right) const {
        if (split.spatial) {
            left.refs = std::move(split.left);
            right.refs = std::move(split.right);
            left.box = split.left_box;
            right.box = split.right_box;
        } else {
            apply_object_split(task.refs, split.sorted, split.object, left.refs, right.refs);
            left.box = split.object.left;
            right.box = split.object.right;
        }
        hand_down_spare(task, left, right);
        split = SbvhSplit{};  // spent: its sorted axes are not kept while the children are built
    }
    // Object median on the axis where the centres spread most.
    void partition_at_median(SbvhTask& task, SbvhSplit& split, SbvhTask& left, SbvhTask& right) const {
        split.object = median_split(task.refs, split.sorted);
        split.spatial = false;
        partition(task, split, left, right);
    }
    // Takes leaf slots (in x order, as the sweep SAH builder lays leaves out).
    uint32_t place_leaf(SbvhTask& task) {
        std::vector<Ref>& refs = task.refs;
        const auto n = static_cast<uint32_t>(refs.size());
        const uint32_t slot = next_slot_.fetch_add(n, std::memory_order_relaxed);
        if (size_t{slot} + n > slots_.size()) throw Error("SBVH build: reference budget exceeded (internal error)");
        std::sort(refs.begin(), refs.end(), [](const Ref& a, const Ref& b) {
            return sweep::sort_key(a.centre(0), a.id) < sweep::sort_key(b.centre(0), b.id);
        });
        for (uint32_t i = 0; i < n; ++i) slots_[slot + i] = refs[i].id;
        return slot;
    }
    [[nodiscard]] uint32_t slot_prim(uint32_t slot) const { return slots_[slot]; }
    static SpareRefs leaf_carry(const SbvhTask& task) { return task.spare; }
    static void hand_over(SpareRefs left_rest, SbvhTask& right) { right.spare += left_rest; }

    // ---- Object splits.

    // Full sweep over the references sorted by centre on each axis.
    ObjectSplit find_object_split(const std::vector<Ref>& refs, SortedAxes& sorted) const {
        const auto n = static_cast<uint32_t>(refs.size());
        ObjectSplit per_axis[3];
        for_axes(n, [&](int axis) {
            std::vector<SortItem>& keys = sorted.keys[axis];
            keys.resize(n);
            for (uint32_t i = 0; i < n; ++i) keys[i] = SortItem{sweep::sort_key(refs[i].centre(axis), refs[i].id), i};
            std::sort(keys.begin(), keys.end());
            std::vector<float> right_area(n);
            Box3f acc;
            for (uint32_t i = n - 1; i > 0; --i) {
                const Ref& r = refs[keys[i].index];
                grow(acc, r.lo, r.hi);
                right_area[i] = acc.surface_area();
            }
            ObjectSplit& best = per_axis[axis];
            best.axis = axis;
            acc = Box3f{};
            for (uint32_t i = 1; i < n; ++i) {
                const Ref& r = refs[keys[i - 1].index];
                grow(acc, r.lo, r.hi);
                const float cost = acc.surface_area() * static_cast<float>(i) + right_area[i] * static_cast<float>(n - i);
                if (best.position == 0 || cost < best.cost) {  // even when costs overflow
                    best.cost = cost;
                    best.position = i;
                }
            }
        });
        int axis = 0;
        for (int a = 1; a < 3; ++a) {
            if (per_axis[a].cost < per_axis[axis].cost) axis = a;
        }
        ObjectSplit best = per_axis[axis];
        side_boxes(refs, sorted.keys[axis], best);
        return best;
    }

    static void side_boxes(const std::vector<Ref>& refs, const std::vector<SortItem>& keys, ObjectSplit& split) {
        split.left = split.right = Box3f{};
        for (size_t i = 0; i < keys.size(); ++i) {
            const Ref& r = refs[keys[i].index];
            grow(i < split.position ? split.left : split.right, r.lo, r.hi);
        }
    }

    // Object median on the axis where the centres spread most.
    static ObjectSplit median_split(const std::vector<Ref>& refs, const SortedAxes& sorted) {
        const size_t n = refs.size();
        ObjectSplit split;
        float widest = -1.0f;
        for (int a = 0; a < 3; ++a) {
            const float extent = refs[sorted.keys[a][n - 1].index].centre(a) -
                                 refs[sorted.keys[a][0].index].centre(a);
            if (extent > widest) {
                widest = extent;
                split.axis = a;
            }
        }
        split.position = static_cast<uint32_t>(n / 2);
        side_boxes(refs, sorted.keys[split.axis], split);
        return split;
    }

    // ---- Spatial splits.

    // Where the children of the object split overlap by more than alpha times
    // the root's area: the best spatial candidate that fits the spare
    // references and the depth limit, applied, becomes `split` where its
    // children's SAH is below the object split's.
    void try_spatial_split(const SbvhTask& task, int depth, SbvhSplit& split) const {
        const Box3f overlap = intersect(split.object.left, split.object.right);
        if (empty_box(overlap) || !(overlap.surface_area() > alpha_ * root_area_)) return;
        const SpatialSplit spatial = find_spatial_split(task.refs, task.box, task.spare);
        if (!spatial.valid()) return;
        // Deep in the tree a lopsided split could exceed kBvhMaxDepth.
        const uint32_t larger = std::max(spatial.left_count, spatial.right_count);
        if (!top_down::depth_allows(depth, larger, max_leaf_size())) return;
        std::vector<Ref> left, right;
        Box3f left_box, right_box;
        if (!apply_spatial_split(task.refs, task.box, spatial, left, right, left_box, right_box)) return;
        const float cost = left_box.surface_area() * static_cast<float>(left.size()) +
                           right_box.surface_area() * static_cast<float>(right.size());
        if (!(cost < split.object.cost)) return;
        split.spatial = true;
        split.spatial_larger = larger;
        split.spatial_cost = cost;
        split.left = std::move(left);
        split.right = std::move(right);
        split.left_box = left_box;
        split.right_box = right_box;
    }

    // Chopped-reference binning and a sweep over the slab boundaries; only
    // splits that fit in `spare` extra references are considered.
    SpatialSplit find_spatial_split(const std::vector<Ref>& refs, const Box3f& bounds, uint64_t spare) const {
        const size_t n = refs.size();
        SpatialSplit per_axis[3];
        for_axes(n, [&](int axis) {
            const SlabMap map(bounds, axis, spatial_bins(n));
            const int bins = map.bins;
            if (!map.usable()) return;
            Box3f bin_box[kSpatialBins];
            uint32_t enter[kSpatialBins] = {}, exit[kSpatialBins] = {};
            for (const Ref& r : refs) {
                const int first = map.bin(r.lo[axis]);
                const int last = map.bin(r.hi[axis]);
                ++enter[first];
                ++exit[last];
                if (first == last) {
                    grow(bin_box[first], r.lo, r.hi);
                    continue;
                }
                chop_into_slabs(triangles_[r.id], r.box(), axis, map, first, last, bin_box);
            }
            float right_area[kSpatialBins];
            uint32_t right_count[kSpatialBins];
            Box3f acc;
            uint32_t count = 0;
            for (int k = bins - 1; k > 0; --k) {
                grow(acc, bin_box[k]);
                count += exit[k];
                right_area[k] = acc.surface_area();
                right_count[k] = count;
            }
            SpatialSplit& best = per_axis[axis];
            acc = Box3f{};
            count = 0;
            for (int k = 1; k < bins; ++k) {
                grow(acc, bin_box[k - 1]);
                count += enter[k - 1];
                if (count == 0 || right_count[k] == 0) continue;
                if (uint64_t{count} + right_count[k] - n > spare) continue;
                const float cost = acc.surface_area() * static_cast<float>(count) +
                                   right_area[k] * static_cast<float>(right_count[k]);
                if (!best.valid() || cost < best.cost) best = SpatialSplit{axis, k, bins, cost, count, right_count[k]};
            }
        });
        SpatialSplit best;
        for (const SpatialSplit& s : per_axis) {
            if (s.valid() && (!best.valid() || s.cost < best.cost)) best = s;
        }
        return best;
    }

    // Distributes refs by the object split; left/right get the side boxes.
    static void apply_object_split(const std::vector<Ref>& refs, const SortedAxes& sorted, const ObjectSplit& split,
                                   std::vector<Ref>& left, std::vector<Ref>& right) {
        const std::vector<SortItem>& keys = sorted.keys[split.axis];
        left.reserve(split.position);
        right.reserve(keys.size() - split.position);
        for (size_t i = 0; i < keys.size(); ++i) {
            (i < split.position ? left : right).push_back(refs[keys[i].index]);
        }
    }

    // Distributes refs by the spatial split with reference unsplitting; false
    // (and nothing useful in left/right) when one side would end up empty.
    bool apply_spatial_split(const std::vector<Ref>& refs, const Box3f& bounds, const SpatialSplit& split,
                             std::vector<Ref>& left, std::vector<Ref>& right, Box3f& left_box,
                             Box3f& right_box) const {
        const int axis = split.axis;
        const SlabMap map(bounds, axis, split.bins);
        const float pos = map.plane(split.plane);
        left.reserve(split.left_count);
        right.reserve(split.right_count);
        left_box = right_box = Box3f{};
        std::vector<uint32_t> straddling;
        for (uint32_t i = 0; i < refs.size(); ++i) {
            const Ref& r = refs[i];
            if (map.bin(r.hi[axis]) < split.plane) {
                left.push_back(r);
                grow(left_box, r.lo, r.hi);
            } else if (map.bin(r.lo[axis]) >= split.plane) {
                right.push_back(r);
                grow(right_box, r.lo, r.hi);
            } else {
                straddling.push_back(i);
            }
        }
        for (const uint32_t i : straddling) {
            const Ref& r = refs[i];
            Box3f l, rr;
            split_box(triangles_[r.id], r.box(), axis, pos, l, rr);
            const bool l_empty = empty_box(l), r_empty = empty_box(rr);
            if (l_empty && r_empty) {  // cannot happen for a valid reference; keep it whole
                l = r.box();
            }
            if (r_empty || l_empty) {
                const bool to_left = r_empty;
                const Box3f& piece = to_left ? l : rr;
                (to_left ? left : right).push_back(Ref{piece.lo, r.id, piece.hi});
                grow(to_left ? left_box : right_box, piece);
                continue;
            }
            const auto nl = static_cast<float>(left.size()), nr = static_cast<float>(right.size());
            const Box3f whole = r.box();
            const float split_cost = merge(left_box, l).surface_area() * (nl + 1.0f) +
                                     merge(right_box, rr).surface_area() * (nr + 1.0f);
            const float left_cost = merge(left_box, whole).surface_area() * (nl + 1.0f) +
                                    right_box.surface_area() * nr;
            const float right_cost = left_box.surface_area() * nl +
                                     merge(right_box, whole).surface_area() * (nr + 1.0f);
            if (left_cost <= split_cost && left_cost <= right_cost) {
                left.push_back(r);
                grow(left_box, whole);
            } else if (right_cost <= split_cost) {
                right.push_back(r);
                grow(right_box, whole);
            } else {
                left.push_back(Ref{l.lo, r.id, l.hi});
                grow(left_box, l);
                right.push_back(Ref{rr.lo, r.id, rr.hi});
                grow(right_box, rr);
            }
        }
        return !left.empty() && !right.empty();
    }

    // ---- The reference budget.

    // The spare references a split leaves over go to its children in
    // proportion to their SAH weights (area times references): spatial
    // splits pay off, and use references, where triangles are large for
    // their node, and a share by reference count alone starves those
    // subtrees while most of the budget goes unused in dense ones.
    static std::pair<uint64_t, uint64_t> share_spare(uint64_t rest, size_t left, size_t right,
                                                     const Box3f& left_box, const Box3f& right_box) {
        const double wl = static_cast<double>(left_box.surface_area()) * static_cast<double>(left);
        const double wr = static_cast<double>(right_box.surface_area()) * static_cast<double>(right);
        const double f = (wl + wr > 0.0 && std::isfinite(wl + wr))
                             ? wl / (wl + wr)
                             : static_cast<double>(left) / static_cast<double>(left + right);
        const uint64_t left_spare = std::min<uint64_t>(rest, static_cast<uint64_t>(f * static_cast<double>(rest)));
        return {left_spare, rest - left_spare};
    }

    // Checks the references the split added against the node's spare ones,
    // hands the rest down to the children and frees the node's references.
    static void hand_down_spare(SbvhTask& task, SbvhTask& left, SbvhTask& right) {
        const uint64_t used = left.refs.size() + right.refs.size() - task.refs.size();
        if (used > task.spare) throw Error("SBVH build: reference budget exceeded (internal error)");
        std::vector<Ref>().swap(task.refs);
        const auto [left_spare, right_spare] =
            share_spare(task.spare - used, left.refs.size(), right.refs.size(), left.box, right.box);
        left.spare = left_spare;
        right.spare = right_spare;
    }

    std::span<const Triangle> triangles_;
    float alpha_;
    float root_area_ = 0.0f;
    std::vector<uint32_t> slots_;  // leaf slots in allocation order
    std::atomic<uint32_t> next_slot_{0};
};

}  // namespace

Bvh build_sbvh(std::span<const Triangle> triangles, const BvhBuildConfig& config, const SbvhOptions& sbvh) {
    SbvhBuilder builder(triangles, config, sbvh);
    return builder.build();
}

}  // namespace rf
