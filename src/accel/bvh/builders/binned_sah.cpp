// Binned SAH builder (Wald 2007, "On fast Construction of SAH-based Bounding
// Volume Hierarchies").
//
// Top-down: each node's primitive centroids are counted into `bin_count` bins
// per axis, a sweep over the bins evaluates the SAH for every bin boundary on
// all three axes, and the primitive references are partitioned in place.
// From the top-down skeleton (top_down_sah.h) it takes the recursion, the
// leaf decision and its fallbacks (the object median where no bin boundary
// splits or the depth limit is near), the node allocation, subtree tasks and
// the depth-first copy; this file finds the split and partitions.
//
// Data layout: every primitive's box is computed once into a 32-byte,
// 32-byte aligned record (lo, triangle index, hi, padding), so binning and
// partitioning load it as two float4 and grow boxes with SIMD min/max
// (core/simd.h). A node's bins are swept over the non-empty bins only
// (a boundary inside a run of empty bins costs the same as the first one,
// which is the one chosen), found from a bit mask. Scratch arrays are left
// uninitialised, and large ones are asked for transparent huge pages, as
// their page faults otherwise cost about as much as writing them. Leaves
// name ranges of the partitioned records, which are already in depth-first
// order.
//
// Most nodes are small, so their fixed costs matter: a node of two
// primitives needs no bins at all, up to 16 primitives only the bins in use
// are initialised, and up to 64 the partition works from a bit mask of the
// sides instead of a branchy loop. Larger ranges bin odd and even primitives
// into two sets, halving the chains of dependent updates of one bin. All of
// these give exactly the splits, the primitive order and the bounds of the
// plain algorithm.
//
// Parallelism (TBB, through core/parallel.h): large nodes bin their
// primitives in parallel; the skeleton builds subtrees above a size
// threshold as separate tasks and copies the task-ordered tree into
// depth-first order. Every decision depends only on the primitives of a
// node, and parallel binning only merges counts and min/max bounds, so the
// output is identical for every thread count.
#include "accel/bvh/builders/binned_sah.h"

#include <algorithm>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <memory>
#include <type_traits>

#include "accel/bvh/builders/sweep_common.h"
#include "accel/bvh/builders/top_down_sah.h"
#include "core/parallel.h"
#include "core/simd.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

using Float4 = simd::vfloat<4>;  // loads and stores 16-byte aligned
using simd::add;
using simd::load;
using simd::mul;
using simd::set1;
using simd::std_max;
using simd::std_min;
using simd::store;
using simd::sub;
using simd::xyz0;

constexpr int kMaxBins = 256;
constexpr uint32_t kSmallNodeSize = 16;               // prims per node to initialise only the bins in use
constexpr uint32_t kSmallPartitionSize = 64;          // prims per node to partition by bit mask (at most 64)
constexpr uint32_t kTwoSetBinningSize = 256;          // prims per range to bin into two sets
constexpr uint32_t kParallelBinningSize = 64 * 1024;  // prims per node to bin in parallel
constexpr uint32_t kGrainSize = 16 * 1024;

inline Box3f to_box(Float4 lo, Float4 hi) {
    alignas(16) float l[4], h[4];
    store<4>(l, lo);
    store<4>(h, hi);
    return {{l[0], l[1], l[2]}, {h[0], h[1], h[2]}};
}

// A primitive's bounds plus the triangle it came from; partitioning moves
// these 32-byte records so that every pass streams through memory. Plain
// data, so arrays of them are not zero-filled.
struct alignas(32) PrimRef {
    float lo[3];
    uint32_t id;
    float hi[3];
    uint32_t unused;
    [[nodiscard]] Float4 lo4() const { return load<4>(lo); }  // lane 3 holds the id: no arithmetic on it
    [[nodiscard]] Float4 hi4() const { return load<4>(hi); }
    [[nodiscard]] Float4 centroid4() const { return mul(add(xyz0(lo4()), xyz0(hi4())), set1<4>(0.5f)); }
};
static_assert(sizeof(PrimRef) == 32 && std::is_trivially_default_constructible_v<PrimRef>);

// Bounds of a set of primitives and of their centroids (lane 3 unused).
struct RangeBounds {
    Float4 lo = set1<4>(FLT_MAX), hi = set1<4>(-FLT_MAX);
    Float4 clo = set1<4>(FLT_MAX), chi = set1<4>(-FLT_MAX);
    void add(const PrimRef& p) { add(p.lo4(), p.hi4()); }
    // A primitive by its bounds as loaded by PrimRef::lo4 and hi4.
    void add(Float4 l, Float4 h) {
        lo = std_min(lo, l);
        hi = std_max(hi, h);
        const Float4 c = mul(simd::add(xyz0(l), xyz0(h)), set1<4>(0.5f));  // PrimRef::centroid4
        clo = std_min(clo, c);
        chi = std_max(chi, c);
    }
    void add(const RangeBounds& o) {
        lo = std_min(lo, o.lo);
        hi = std_max(hi, o.hi);
        clo = std_min(clo, o.clo);
        chi = std_max(chi, o.chi);
    }
    [[nodiscard]] Box3f bounds() const { return to_box(lo, hi); }
    [[nodiscard]] Box3f centroids() const { return to_box(clo, chi); }
};

// Maps centroids to bins along each axis of a node's centroid bounds.
struct BinMapping {
    Float4 origin;
    Float4 scale;  // bins per unit length; 0 on axes where all centroids coincide
    Float4 last;   // bin_count - 1
    bool usable[3];

    BinMapping(const Box3f& centroids, int bins) {
        const Vec3f extent = centroids.extent();
        float s[3];
        for (int axis = 0; axis < 3; ++axis) {
            // Slightly less than bins / extent so the largest centroid lands in the last bin.
            const float t = static_cast<float>(bins) * (1.0f - 0x1p-20f) / extent[axis];
            s[axis] = (extent[axis] > 0.0f && std::isfinite(t)) ? t : 0.0f;
            usable[axis] = s[axis] > 0.0f;
        }
        origin = simd::set(centroids.lo.x, centroids.lo.y, centroids.lo.z, 0.0f);
        scale = simd::set(s[0], s[1], s[2], 0.0f);
        last = set1<4>(static_cast<float>(bins - 1));
    }
    // The bin of p's centroid on each axis, as a float: x > 0 ? x : 0 (NaN
    // to 0), then x < last ? x : last, to be truncated.
    [[nodiscard]] Float4 bin_positions(const PrimRef& p) const {
        const Float4 x = mul(sub(p.centroid4(), origin), scale);
        return simd::min(simd::max(x, set1<4>(0.0f)), last);
    }
    void indices(const PrimRef& p, int32_t* out) const { simd::store_truncated(out, bin_positions(p)); }
    // Whether the bin of p's centroid on `axis` is below the bin `bin` (all
    // lanes: its index as a float), without a round trip through memory, for
    // partitioning: a position in [0, last] truncates to below an integer
    // exactly where it is below it.
    [[nodiscard]] bool below(const PrimRef& p, int axis, Float4 bin) const {
        return ((simd::bits(simd::cmp_lt(bin_positions(p), bin)) >> axis) & 1u) != 0;
    }
};

// Per axis: bin boxes (lane 3 unused), counts and a mask of the non-empty
// bins. Plain data: only bins in use get initialised. Stored bin by bin,
// the three axes and both sides of a box next to each other, so that one
// primitive's updates touch few lines and no two of them lie a multiple of
// 4 KiB apart (the CPU would suspect a load of depending on the store).
struct BinSet {
    static constexpr int kMaskWords = kMaxBins / 64;
    struct Box {
        alignas(16) float lo[4];
        float hi[4];
    };
    Box box[kMaxBins][3];
    uint32_t counts[kMaxBins][3];
    uint64_t used[3][kMaskWords];

    float* lo(int axis, int i) { return box[i][axis].lo; }
    float* hi(int axis, int i) { return box[i][axis].hi; }
    uint32_t& count(int axis, int i) { return counts[i][axis]; }
    [[nodiscard]] const float* lo(int axis, int i) const { return box[i][axis].lo; }
    [[nodiscard]] const float* hi(int axis, int i) const { return box[i][axis].hi; }
    [[nodiscard]] uint32_t count(int axis, int i) const { return counts[i][axis]; }

    void clear(int bin_count) {
        for (int axis = 0; axis < 3; ++axis) {
            for (int i = 0; i < bin_count; ++i) {
                store<4>(lo(axis, i), set1<4>(FLT_MAX));
                store<4>(hi(axis, i), set1<4>(-FLT_MAX));
                count(axis, i) = 0;
            }
        }
    }
    void add(const BinMapping& map, const PrimRef& p) {
        alignas(16) int32_t bin[4];
        map.indices(p, bin);
        add(bin, p);
    }
    void add(const int32_t* bin, const PrimRef& p) {
        const Float4 l = p.lo4(), h = p.hi4();
        for (int axis = 0; axis < 3; ++axis) {
            const int b = bin[axis];
            store<4>(lo(axis, b), std_min(load<4>(lo(axis, b)), l));
            store<4>(hi(axis, b), std_max(load<4>(hi(axis, b)), h));
            ++count(axis, b);
        }
    }
    // Bins a few primitives (at most kSmallNodeSize) without clearing every
    // bin: the bins they fall into are first set to the box of one of them
    // and a zero count, and marked used; adding them all then gives the
    // same bins as clear() and add() would.
    void bin_sparse(const BinMapping& map, const PrimRef* prims, uint32_t n) {
        alignas(16) int32_t bins[kSmallNodeSize][4];
        for (int axis = 0; axis < 3; ++axis) {
            for (uint64_t& word : used[axis]) word = 0;
        }
        for (uint32_t k = 0; k < n; ++k) {
            map.indices(prims[k], bins[k]);
            const Float4 l = prims[k].lo4(), h = prims[k].hi4();
            for (int axis = 0; axis < 3; ++axis) {
                const int b = bins[k][axis];
                store<4>(lo(axis, b), l);
                store<4>(hi(axis, b), h);
                count(axis, b) = 0;
                used[axis][b / 64] |= uint64_t{1} << (b % 64);
            }
        }
        for (uint32_t k = 0; k < n; ++k) add(bins[k], prims[k]);
    }
    // Marks the non-empty bins after clear() and add().
    void mark_used(int bin_count) {
        for (int axis = 0; axis < 3; ++axis) {
            for (uint64_t& word : used[axis]) word = 0;
            for (int i = 0; i < bin_count; ++i) {
                used[axis][i / 64] |= uint64_t{count(axis, i) != 0} << (i % 64);
            }
        }
    }
    // The non-empty bins of `axis` in ascending order; returns their number.
    int used_bins(int axis, int* out) const {
        int m = 0;
        for (int w = 0; w < kMaskWords; ++w) {
            for (uint64_t bits = used[axis][w]; bits != 0; bits &= bits - 1) {
                out[m++] = w * 64 + std::countr_zero(bits);
            }
        }
        return m;
    }
    void merge(const BinSet& o, int bin_count) {
        for (int axis = 0; axis < 3; ++axis) {
            for (int i = 0; i < bin_count; ++i) {
                store<4>(lo(axis, i), std_min(load<4>(lo(axis, i)), load<4>(o.lo(axis, i))));
                store<4>(hi(axis, i), std_max(load<4>(hi(axis, i)), load<4>(o.hi(axis, i))));
                count(axis, i) += o.count(axis, i);
            }
        }
    }
};
static_assert(kMaxBins % 64 == 0);

// Box3f::surface_area of a non-empty box, 2 * (x * y + y * z + z * x) in
// the same order of operations, so the result is the same bit for bit.
inline float surface_area(Float4 lo, Float4 hi) {
    const Float4 e = sub(xyz0(hi), xyz0(lo));
    const Float4 p = mul(e, simd::shuffle<1, 2, 0, 3>(e));  // xy, yz, zx
    return 2.0f * ((simd::lane<0>(p) + simd::lane<1>(p)) + simd::lane<2>(p));
}

// A split plane: primitives whose centroid bin on `axis` is below `bin` go left.
struct Split {
    int axis = -1;
    int bin = 0;
    float cost = kInfinity;  // sum of area * count over both children
    uint32_t left_count = 0;
    [[nodiscard]] bool valid() const { return axis >= 0; }
};

// The skeleton's view of a node: its primitives refs_[begin, end) and their bounds.
struct BinnedTask {
    uint32_t begin = 0, end = 0;
    RangeBounds range;
    [[nodiscard]] uint32_t count() const { return end - begin; }
    [[nodiscard]] Box3f bounds() const { return range.bounds(); }
};

// The best bin boundary of a node, with the node's bins (to partition by).
struct BinnedSplit {
    BinMapping map;
    Split plane;
    [[nodiscard]] bool valid() const { return plane.valid(); }
    [[nodiscard]] float cost() const { return plane.cost; }
    [[nodiscard]] uint32_t larger_child(uint32_t count) const {
        return std::max(plane.left_count, count - plane.left_count);
    }
};

class BinnedSahBuilder : public top_down::TopDownSahBuilder<BinnedSahBuilder, BinnedTask> {
public:
    BinnedSahBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const BinnedSahOptions& binned)
        : TopDownSahBuilder(config), triangles_(triangles), bin_count_(binned.bin_count) {}

    Bvh build() {
        const uint32_t count = checked_index_count("BVH primitive count", triangles_.size());
        if (count == 0) return Bvh{};
        refs_ = top_down::scratch_array<PrimRef>(count, "BVH build: primitive references");
        BinnedTask root{0, count, make_prim_refs(count)};
        return build_tree(root, count);
    }

private:
    friend TopDownSahBuilder;
    static constexpr const char* kName = "BVH build";
    static constexpr uint32_t kParallelSubtreeSize = 1024;  // prims per node to spawn child tasks
    static constexpr bool kLeavesInPlace = true;

    RangeBounds make_prim_refs(uint32_t count) {
        return parallel::reduce(
            0u, count, kGrainSize, RangeBounds{},
            [&](uint32_t lo, uint32_t hi, RangeBounds acc) {
                for (uint32_t i = lo; i != hi; ++i) {
                    const Triangle& t = triangles_[i];
                    const Vec3f l = sweep::vmin(t.v0, sweep::vmin(t.v1, t.v2));
                    const Vec3f h = sweep::vmax(t.v0, sweep::vmax(t.v1, t.v2));
                    refs_[i] = PrimRef{{l.x, l.y, l.z}, i, {h.x, h.y, h.z}, 0};
                    acc.add(refs_[i]);
                }
                return acc;
            },
            [](RangeBounds a, const RangeBounds& b) { a.add(b); return a; });
    }

    // ---- The skeleton's hooks.

    BinnedSplit find_split(const BinnedTask& task, int /*depth*/) const {
        BinnedSplit split{BinMapping(task.range.centroids(), bin_count_), Split{}};
        split.plane = best_plane(task.begin, task.end, split.map);
        return split;
    }
    void partition(const BinnedTask& task, const BinnedSplit& split, BinnedTask& left, BinnedTask& right) {
        const uint32_t mid = partition_by_bin(task.begin, task.end, split.map, split.plane, left.range, right.range);
        set_ranges(task, mid, left, right);
    }
    void partition_at_median(const BinnedTask& task, const BinnedSplit& /*split*/, BinnedTask& left,
                             BinnedTask& right) {
        const uint32_t mid = partition_by_median(task.begin, task.end, task.range.centroids(), left.range, right.range);
        set_ranges(task, mid, left, right);
    }
    static uint32_t place_leaf(const BinnedTask& task) { return task.begin; }
    [[nodiscard]] uint32_t slot_prim(uint32_t slot) const { return refs_[slot].id; }

    static void set_ranges(const BinnedTask& task, uint32_t mid, BinnedTask& left, BinnedTask& right) {
        left.begin = task.begin;
        left.end = mid;
        right.begin = mid;
        right.end = task.end;
    }

    // ---- Binning.

    void bin_range(uint32_t begin, uint32_t end, const BinMapping& map, BinSet& set) const {
        set.clear(bin_count_);
        if (end - begin < kParallelBinningSize) {
            bin_prims(begin, end, map, set);
            return;
        }
        // Chunks bin into their own sets (heap-allocated: a BinSet is large),
        // merged afterwards in chunk order.
        const uint32_t chunks = (end - begin + kGrainSize - 1) / kGrainSize;
        std::unique_ptr<BinSet[]> partial(new BinSet[chunks]);
        parallel::for_range(0u, chunks, 1u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t c = lo; c != hi; ++c) {
                BinSet& s = partial[c];
                s.clear(bin_count_);
                const uint32_t first = begin + c * kGrainSize, last = std::min(end, first + kGrainSize);
                bin_prims(first, last, map, s);
            }
        });
        for (uint32_t c = 0; c < chunks; ++c) set.merge(partial[c], bin_count_);
    }

    // Adds refs_[first, last) to `set`. Neighbouring primitives often share
    // bins, so each bin update waits for the previous one; in larger ranges
    // odd primitives go to a second set, merged at the end, which halves
    // those chains.
    void bin_prims(uint32_t first, uint32_t last, const BinMapping& map, BinSet& set) const {
        if (last - first < kTwoSetBinningSize) {
            for (uint32_t i = first; i < last; ++i) set.add(map, refs_[i]);
            return;
        }
        BinSet odd;
        odd.clear(bin_count_);
        uint32_t i = first;
        for (; i + 1 < last; i += 2) {
            set.add(map, refs_[i]);
            odd.add(map, refs_[i + 1]);
        }
        if (i < last) set.add(map, refs_[i]);
        set.merge(odd, bin_count_);
    }

    // The cheapest bin boundary over all three axes (invalid when every
    // centroid falls into one bin on every axis).
    Split best_plane(uint32_t begin, uint32_t end, const BinMapping& map) const {
        Split best;
        if (!map.usable[0] && !map.usable[1] && !map.usable[2]) return best;
        if (end - begin == 2) return best_plane_of_pair(begin, map);
        BinSet set;  // plain data: only the bins in use get initialised
        if (end - begin <= kSmallNodeSize) {
            set.bin_sparse(map, refs_.get() + begin, end - begin);
        } else {
            bin_range(begin, end, map, set);
            set.mark_used(bin_count_);
        }
        for (int axis = 0; axis < 3; ++axis) {
            if (map.usable[axis]) sweep(set, axis, best);
        }
        return best;
    }

    // best_plane for two primitives: every axis that puts them into
    // different bins splits them apart at the same cost (the same two boxes,
    // and float addition commutes), so the first such axis is the one the
    // sweep keeps, at the boundary after the lower bin.
    Split best_plane_of_pair(uint32_t begin, const BinMapping& map) const {
        const PrimRef& a = refs_[begin];
        const PrimRef& b = refs_[begin + 1];
        alignas(16) int32_t bin_a[4], bin_b[4];
        map.indices(a, bin_a);
        map.indices(b, bin_b);
        for (int axis = 0; axis < 3; ++axis) {
            if (!map.usable[axis] || bin_a[axis] == bin_b[axis]) continue;
            const bool a_lower = bin_a[axis] < bin_b[axis];
            const PrimRef& lower = a_lower ? a : b;
            const PrimRef& upper = a_lower ? b : a;
            const float cost = surface_area(lower.lo4(), lower.hi4()) * 1.0f + surface_area(upper.lo4(), upper.hi4()) * 1.0f;
            return Split{axis, std::min(bin_a[axis], bin_b[axis]) + 1, cost, 1};
        }
        return Split{};
    }

    // Evaluates the boundary just after each non-empty bin of `axis` but the
    // last, keeping the first cheapest in `best` (axes in order, bins
    // ascending). Every boundary in a run of empty bins costs the same, and
    // the first of them is the one a sweep over all bins keeps.
    static void sweep(const BinSet& set, int axis, Split& best) {
        int used[kMaxBins];
        const int m = set.used_bins(axis, used);
        float right_area[kMaxBins];
        uint32_t right_count[kMaxBins];
        // Suffix sweep: right side of the boundary before used bin t.
        Float4 lo = set1<4>(FLT_MAX), hi = set1<4>(-FLT_MAX);
        uint32_t n = 0;
        for (int t = m - 1; t > 0; --t) {
            const int i = used[t];
            lo = std_min(lo, load<4>(set.lo(axis, i)));
            hi = std_max(hi, load<4>(set.hi(axis, i)));
            n += set.count(axis, i);
            right_area[t] = surface_area(lo, hi);
            right_count[t] = n;
        }
        // Prefix sweep: evaluate the boundary after each used bin but the last.
        lo = set1<4>(FLT_MAX);
        hi = set1<4>(-FLT_MAX);
        n = 0;
        for (int t = 0; t + 1 < m; ++t) {
            const int i = used[t];
            lo = std_min(lo, load<4>(set.lo(axis, i)));
            hi = std_max(hi, load<4>(set.hi(axis, i)));
            n += set.count(axis, i);
            const float cost = surface_area(lo, hi) * static_cast<float>(n) +
                               right_area[t + 1] * static_cast<float>(right_count[t + 1]);
            if (!best.valid() || cost < best.cost) best = Split{axis, i + 1, cost, n};  // even when costs overflow
        }
    }

    // ---- Partitioning.

    // Hoare partition of refs_[begin, end) by the split; fills both sides' bounds.
    uint32_t partition_by_bin(uint32_t begin, uint32_t end, const BinMapping& map, const Split& split,
                              RangeBounds& left, RangeBounds& right) {
        if (end - begin <= kSmallPartitionSize) return partition_small(begin, end, map, split, left, right);
        const int axis = split.axis;
        const Float4 bin = set1<4>(static_cast<float>(split.bin));
        auto goes_left = [&](const PrimRef& p) { return map.below(p, axis, bin); };
        PrimRef* refs = refs_.get();
        RangeBounds l, r;  // locals stay in registers
        uint32_t i = begin, j = end;
        for (;;) {
            while (i < j && goes_left(refs[i])) l.add(refs[i++]);
            while (i < j && !goes_left(refs[j - 1])) r.add(refs[--j]);
            if (i >= j) break;
            // Swapped through registers (reading back the stores stalls), and
            // both sides of the pair are known: no need to test them again.
            PrimRef& a = refs[i++];
            PrimRef& b = refs[--j];
            const Float4 a_lo = a.lo4(), a_hi = a.hi4(), b_lo = b.lo4(), b_hi = b.hi4();
            store<4>(a.lo, b_lo);  // lane 3: the id
            store<4>(a.hi, b_hi);
            store<4>(b.lo, a_lo);
            store<4>(b.hi, a_hi);
            l.add(b_lo, b_hi);
            r.add(a_lo, a_hi);
        }
        left = l;
        right = r;
        return i;
    }

    // partition_by_bin for at most 64 primitives, without the Hoare loop's
    // unpredictable branches but with its result: the sides are found first,
    // as a bit mask, then Hoare's swaps are made (the t-th right-goer from
    // the left with the t-th left-goer from the right, while they are
    // misplaced) and the bounds accumulated in its order (left side
    // ascending, right side descending), so even signed zeros agree.
    uint32_t partition_small(uint32_t begin, uint32_t end, const BinMapping& map, const Split& split,
                             RangeBounds& left, RangeBounds& right) {
        PrimRef* refs = refs_.get() + begin;
        const uint32_t n = end - begin;
        const Float4 bin = set1<4>(static_cast<float>(split.bin));
        uint64_t goes_left = 0;
        for (uint32_t k = 0; k < n; ++k) {
            goes_left |= uint64_t{map.below(refs[k], split.axis, bin)} << k;
        }
        const uint32_t mid = static_cast<uint32_t>(std::popcount(goes_left));
        const uint64_t low = mid == 64 ? ~uint64_t{0} : (uint64_t{1} << mid) - 1;
        uint64_t misplaced_low = ~goes_left & low;   // right-goers below mid, ascending
        uint64_t misplaced_high = goes_left & ~low;  // left-goers from mid on, descending
        while (misplaced_low != 0) {
            const int a = std::countr_zero(misplaced_low);
            const int b = 63 - std::countl_zero(misplaced_high);
            std::swap(refs[a], refs[b]);
            misplaced_low &= misplaced_low - 1;
            misplaced_high &= ~(uint64_t{1} << b);
        }
        RangeBounds l, r;
        for (uint32_t k = 0; k < mid; ++k) l.add(refs[k]);
        for (uint32_t k = n; k-- > mid;) r.add(refs[k]);
        left = l;
        right = r;
        return begin + mid;
    }

    // Object median along the widest centroid axis (ties broken by triangle
    // index, so the order is total); halves by position when all centroids coincide.
    uint32_t partition_by_median(uint32_t begin, uint32_t end, const Box3f& centroids, RangeBounds& left,
                                 RangeBounds& right) {
        const uint32_t mid = begin + (end - begin) / 2;
        const Vec3f extent = centroids.extent();
        PrimRef* refs = refs_.get();
        if (extent.x > 0.0f || extent.y > 0.0f || extent.z > 0.0f) {
            const int axis = centroids.largest_axis();
            std::nth_element(refs + begin, refs + mid, refs + end, [axis](const PrimRef& a, const PrimRef& b) {
                const float ca = a.lo[axis] + a.hi[axis], cb = b.lo[axis] + b.hi[axis];
                return ca < cb || (ca == cb && a.id < b.id);
            });
        }
        for (uint32_t i = begin; i < mid; ++i) left.add(refs[i]);
        for (uint32_t i = mid; i < end; ++i) right.add(refs[i]);
        return mid;
    }

    std::span<const Triangle> triangles_;
    int bin_count_;
    std::unique_ptr<PrimRef[]> refs_;
};

}  // namespace

Bvh build_binned_sah(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                     const BinnedSahOptions& binned) {
    BinnedSahBuilder builder(triangles, config, binned);
    return builder.build();
}

}  // namespace rf
