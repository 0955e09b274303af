// Binned SAH builder (Wald 2007, "On fast Construction of SAH-based Bounding
// Volume Hierarchies").
//
// Top-down: each node's primitive centroids are counted into `bin_count` bins
// per axis, a sweep over the bins evaluates the SAH for every bin boundary on
// all three axes, and the primitive references are partitioned in place.
//
// Parallelism (TBB): large nodes bin their primitives in parallel, and
// subtrees above a size threshold are built as separate tasks. Tasks allocate
// child pairs from a shared counter, so the first pass lays nodes out in
// whatever order tasks ran; a second pass copies the tree into depth-first
// order (a node's children pair, then the left subtree, then the right). Every
// decision depends only on the primitives of a node, and parallel binning only
// merges counts and min/max bounds, so the output is identical for every
// thread count.
#include "accel/bvh/build/binned_sah.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"


namespace rf {
namespace {

constexpr int kMaxBins = 256;
constexpr uint32_t kParallelBinningSize = 64 * 1024;  // prims per node to bin in parallel
constexpr uint32_t kParallelSubtreeSize = 1024;       // prims per node to spawn child tasks
constexpr uint32_t kParallelCopySize = 4096;          // nodes per subtree to copy in parallel
constexpr uint32_t kGrainSize = 16 * 1024;

// A primitive's bounds plus the triangle it came from; partitioning moves
// these 32-byte records so that every pass streams through memory.
struct PrimRef {
    Vec3f lo;
    uint32_t id;
    Vec3f hi;
    uint32_t unused;
    [[nodiscard]] Box3f bounds() const { return {lo, hi}; }
    [[nodiscard]] Vec3f centroid() const { return (lo + hi) * 0.5f; }
};

// Box growth with std::min/max, which compile to single instructions (the
// NaN-aware fminf/fmaxf behind Box3f::extend are library calls); inputs are finite.
inline Vec3f vmin(const Vec3f& a, const Vec3f& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f vmax(const Vec3f& a, const Vec3f& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
inline void grow(Box3f& box, const Vec3f& lo, const Vec3f& hi) {
    box.lo = vmin(box.lo, lo);
    box.hi = vmax(box.hi, hi);
}

// Bounds of a set of primitives and of their centroids.
struct RangeBounds {
    Box3f bounds;
    Box3f centroids;
    void add(const PrimRef& p) {
        grow(bounds, p.lo, p.hi);
        const Vec3f c = p.centroid();
        grow(centroids, c, c);
    }
    void add(const RangeBounds& o) {
        grow(bounds, o.bounds.lo, o.bounds.hi);
        grow(centroids, o.centroids.lo, o.centroids.hi);
    }
};

// Maps centroids to bins along each axis of a node's centroid bounds.
struct BinMapping {
    Vec3f origin;
    Vec3f scale;  // bins per unit length; 0 on axes where all centroids coincide
    int bin_count;

    BinMapping(const Box3f& centroids, int bins) : origin(centroids.lo), bin_count(bins) {
        const Vec3f extent = centroids.extent();
        for (int axis = 0; axis < 3; ++axis) {
            // Slightly less than bins / extent so the largest centroid lands in the last bin.
            const float s = static_cast<float>(bins) * (1.0f - 0x1p-20f) / extent[axis];
            scale[axis] = (extent[axis] > 0.0f && std::isfinite(s)) ? s : 0.0f;
        }
    }
    [[nodiscard]] bool usable(int axis) const { return scale[axis] > 0.0f; }
    [[nodiscard]] int index(const Vec3f& c, int axis) const {
        float x = (c[axis] - origin[axis]) * scale[axis];
        x = x > 0.0f ? x : 0.0f;  // also maps NaN to bin 0
        x = x < static_cast<float>(bin_count - 1) ? x : static_cast<float>(bin_count - 1);
        return static_cast<int>(x);
    }
};

// Plain data (no initializers): a BinSet is built per node, and only the
// first bin_count bins of each axis are cleared and used.
struct Bin {
    float lo[3], hi[3];
    uint32_t count;

    void clear() {
        for (int k = 0; k < 3; ++k) { lo[k] = FLT_MAX; hi[k] = -FLT_MAX; }
        count = 0;
    }
    void add(const Vec3f& box_lo, const Vec3f& box_hi) {
        for (int k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], box_lo[k]);
            hi[k] = std::max(hi[k], box_hi[k]);
        }
    }
    void merge(const Bin& o) {
        add(Vec3f(o.lo[0], o.lo[1], o.lo[2]), Vec3f(o.hi[0], o.hi[1], o.hi[2]));
        count += o.count;
    }
    [[nodiscard]] Box3f bounds() const { return {{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}; }
};

struct BinSet {
    Bin bins[3][kMaxBins];

    void clear(int bin_count) {
        for (auto& axis_bins : bins) {
            for (int i = 0; i < bin_count; ++i) axis_bins[i].clear();
        }
    }
    void add(const BinMapping& map, const PrimRef& p) {
        const Vec3f c = p.centroid();
        for (int axis = 0; axis < 3; ++axis) {
            Bin& bin = bins[axis][map.index(c, axis)];
            bin.add(p.lo, p.hi);
            ++bin.count;
        }
    }
    void merge(const BinSet& o, int bin_count) {
        for (int axis = 0; axis < 3; ++axis) {
            for (int i = 0; i < bin_count; ++i) bins[axis][i].merge(o.bins[axis][i]);
        }
    }
};

// A split plane: primitives whose centroid bin on `axis` is below `bin` go left.
struct Split {
    int axis = -1;
    int bin = 0;
    float cost = kInfinity;  // sum of area * count over both children
    uint32_t left_count = 0;
    [[nodiscard]] bool valid() const { return axis >= 0; }
};

// Levels of halving needed until `count` primitives fit in leaves of `leaf_size`.
int median_levels(uint32_t count, uint32_t leaf_size) {
    const uint32_t leaves = (count + leaf_size - 1) / leaf_size;
    return leaves <= 1 ? 0 : std::bit_width(leaves - 1);
}

class BinnedSahBuilder {
public:
    BinnedSahBuilder(std::span<const Triangle> triangles, const BuildOptions& options)
        : triangles_(triangles),
          bin_count_(options.bin_count),
          max_leaf_size_(static_cast<uint32_t>(options.max_leaf_size)),
          traversal_cost_(options.traversal_cost),
          intersection_cost_(options.intersection_cost) {}

    Bvh build() {
        Bvh bvh;
        const uint32_t count = checked_index_count("BVH primitive count", triangles_.size());
        if (count == 0) return bvh;
        budgeted_resize(refs_, count, "BVH build: primitive references");
        const RangeBounds root = make_prim_refs();

        // At most 2n - 1 nodes: every leaf holds at least one primitive.
        budgeted_resize(scratch_, 2 * size_t{count} - 1, "BVH build: scratch nodes");
        budgeted_resize(subtree_size_, scratch_.size(), "BVH build: subtree sizes");
        next_node_.store(1, std::memory_order_relaxed);
        build_node(0, 0, count, root, 0);

        const uint32_t node_count = subtree_size_[0];
        budgeted_resize(bvh.nodes, node_count, "BVH nodes");
        bvh.nodes[0] = scratch_[0];
        copy_descendants(bvh.nodes, 0, 0, 1);

        budgeted_resize(bvh.prim_indices, count, "BVH primitive indices");
        parallel::for_range(0u, count, kGrainSize, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) bvh.prim_indices[i] = refs_[i].id;
        });
        return bvh;
    }

private:
    RangeBounds make_prim_refs() {
        return parallel::reduce(
            0u, static_cast<uint32_t>(refs_.size()), kGrainSize, RangeBounds{},
            [&](uint32_t lo, uint32_t hi, RangeBounds acc) {
                for (uint32_t i = lo; i != hi; ++i) {
                    const Triangle& t = triangles_[i];
                    refs_[i] = PrimRef{vmin(t.v0, vmin(t.v1, t.v2)), i, vmax(t.v0, vmax(t.v1, t.v2)), 0};
                    acc.add(refs_[i]);
                }
                return acc;
            },
            [](RangeBounds a, const RangeBounds& b) { a.add(b); return a; });
    }

    // Builds the subtree of scratch_[node] over refs_[begin, end); returns its node count.
    uint32_t build_node(uint32_t node, uint32_t begin, uint32_t end, const RangeBounds& range, int depth) {
        const uint32_t count = end - begin;
        BvhNode& out = scratch_[node];
        out.bounds = range.bounds;
        if (count <= 1) return make_leaf(node, begin, count);

        const float area = range.bounds.surface_area();
        Split split = find_split(begin, end, range.centroids);
        const float leaf_cost = intersection_cost_ * area * static_cast<float>(count);
        const float split_cost = traversal_cost_ * area + intersection_cost_ * split.cost;
        if (count <= max_leaf_size_ && (!split.valid() || split_cost >= leaf_cost)) {
            return make_leaf(node, begin, count);
        }
        // A lopsided SAH split deep in the tree could exceed kBvhMaxDepth; from
        // here on, halving still reaches leaves in time.
        if (split.valid()) {
            const uint32_t larger = std::max(split.left_count, count - split.left_count);
            if (depth + 1 + median_levels(larger, max_leaf_size_) > kBvhMaxDepth) split = Split{};
        }
        if (!split.valid() && count <= max_leaf_size_) return make_leaf(node, begin, count);

        RangeBounds left, right;
        const uint32_t mid = split.valid() ? partition_by_bin(begin, end, range.centroids, split, left, right)
                                           : partition_by_median(begin, end, range.centroids, left, right);

        const uint32_t pair = next_node_.fetch_add(2, std::memory_order_relaxed);
        out.first = pair;
        out.count = 0;
        uint32_t left_size = 0, right_size = 0;
        if (count > kParallelSubtreeSize) {
            parallel::invoke([&] { left_size = build_node(pair, begin, mid, left, depth + 1); },
                                 [&] { right_size = build_node(pair + 1, mid, end, right, depth + 1); });
        } else {
            left_size = build_node(pair, begin, mid, left, depth + 1);
            right_size = build_node(pair + 1, mid, end, right, depth + 1);
        }
        subtree_size_[node] = 1 + left_size + right_size;
        return subtree_size_[node];
    }

    uint32_t make_leaf(uint32_t node, uint32_t begin, uint32_t count) {
        scratch_[node].first = begin;
        scratch_[node].count = count;
        subtree_size_[node] = 1;
        return 1;
    }

    void bin_range(uint32_t begin, uint32_t end, const BinMapping& map, BinSet& set) const {
        set.clear(bin_count_);
        if (end - begin < kParallelBinningSize) {
            for (uint32_t i = begin; i < end; ++i) set.add(map, refs_[i]);
            return;
        }
        set = parallel::reduce(
            begin, end, kGrainSize, set,
            [&](uint32_t lo, uint32_t hi, BinSet acc) {
                for (uint32_t i = lo; i != hi; ++i) acc.add(map, refs_[i]);
                return acc;
            },
            [&](BinSet a, const BinSet& b) { a.merge(b, bin_count_); return a; });
    }

    // The cheapest bin boundary over all three axes (invalid when every
    // centroid falls into one bin on every axis).
    Split find_split(uint32_t begin, uint32_t end, const Box3f& centroids) const {
        const BinMapping map(centroids, bin_count_);
        Split best;
        if (!map.usable(0) && !map.usable(1) && !map.usable(2)) return best;
        BinSet set;  // plain data: only the bins in use get cleared
        bin_range(begin, end, map, set);

        float right_area[kMaxBins];
        uint32_t right_count[kMaxBins];
        for (int axis = 0; axis < 3; ++axis) {
            if (!map.usable(axis)) continue;
            const Bin* bins = set.bins[axis];
            // Suffix sweep: right side of the boundary before bin i.
            Box3f acc;
            uint32_t n = 0;
            for (int i = bin_count_ - 1; i > 0; --i) {
                grow(acc, bins[i].bounds().lo, bins[i].bounds().hi);
                n += bins[i].count;
                right_area[i] = acc.surface_area();
                right_count[i] = n;
            }
            // Prefix sweep: evaluate every boundary.
            acc = Box3f{};
            n = 0;
            for (int i = 1; i < bin_count_; ++i) {
                grow(acc, bins[i - 1].bounds().lo, bins[i - 1].bounds().hi);
                n += bins[i - 1].count;
                if (n == 0 || right_count[i] == 0) continue;
                const float cost = acc.surface_area() * static_cast<float>(n) +
                                   right_area[i] * static_cast<float>(right_count[i]);
                if (!best.valid() || cost < best.cost) best = Split{axis, i, cost, n};  // even when costs overflow
            }
        }
        return best;
    }

    // Hoare partition of refs_[begin, end) by the split; fills both sides' bounds.
    uint32_t partition_by_bin(uint32_t begin, uint32_t end, const Box3f& centroids, const Split& split,
                              RangeBounds& left, RangeBounds& right) {
        const BinMapping map(centroids, bin_count_);
        auto goes_left = [&](const PrimRef& p) { return map.index(p.centroid(), split.axis) < split.bin; };
        uint32_t i = begin, j = end;
        for (;;) {
            while (i < j && goes_left(refs_[i])) left.add(refs_[i++]);
            while (i < j && !goes_left(refs_[j - 1])) right.add(refs_[--j]);
            if (i >= j) break;
            std::swap(refs_[i], refs_[j - 1]);
        }
        return i;
    }

    // Object median along the widest centroid axis (ties broken by triangle
    // index, so the order is total); halves by position when all centroids coincide.
    uint32_t partition_by_median(uint32_t begin, uint32_t end, const Box3f& centroids, RangeBounds& left,
                                 RangeBounds& right) {
        const uint32_t mid = begin + (end - begin) / 2;
        const Vec3f extent = centroids.extent();
        if (extent.x > 0.0f || extent.y > 0.0f || extent.z > 0.0f) {
            const int axis = centroids.largest_axis();
            std::nth_element(refs_.begin() + begin, refs_.begin() + mid, refs_.begin() + end,
                             [axis](const PrimRef& a, const PrimRef& b) {
                                 const float ca = a.lo[axis] + a.hi[axis], cb = b.lo[axis] + b.hi[axis];
                                 return ca < cb || (ca == cb && a.id < b.id);
                             });
        }
        for (uint32_t i = begin; i < mid; ++i) left.add(refs_[i]);
        for (uint32_t i = mid; i < end; ++i) right.add(refs_[i]);
        return mid;
    }

    // Writes the descendants of scratch_[from] (copied to out[at]) into
    // out[base, base + subtree size - 1): children pair first, then the left
    // subtree's descendants, then the right's.
    void copy_descendants(std::vector<BvhNode>& out, uint32_t from, uint32_t at, uint32_t base) const {
        const BvhNode& node = scratch_[from];
        if (node.is_leaf()) return;
        const uint32_t left = node.first;
        out[at].first = base;
        out[base] = scratch_[left];
        out[base + 1] = scratch_[left + 1];
        const uint32_t left_size = subtree_size_[left];
        const uint32_t right_base = base + 2 + (left_size - 1);
        if (subtree_size_[from] > kParallelCopySize) {
            parallel::invoke([&] { copy_descendants(out, left, base, base + 2); },
                                 [&] { copy_descendants(out, left + 1, base + 1, right_base); });
        } else {
            copy_descendants(out, left, base, base + 2);
            copy_descendants(out, left + 1, base + 1, right_base);
        }
    }

    std::span<const Triangle> triangles_;
    int bin_count_;
    uint32_t max_leaf_size_;
    float traversal_cost_;
    float intersection_cost_;

    std::vector<PrimRef> refs_;
    std::vector<BvhNode> scratch_;         // nodes in allocation order
    std::vector<uint32_t> subtree_size_;   // per scratch node: nodes in its subtree
    std::atomic<uint32_t> next_node_{1};
};

}  // namespace

Bvh build_binned_sah(std::span<const Triangle> triangles, const BuildOptions& options) {
    BinnedSahBuilder builder(triangles, options);
    return parallel::with_threads(options.threads, [&] { return builder.build(); });
}

}  // namespace rf
