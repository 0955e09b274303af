// Binned SAH builder (Wald 2007, "On fast Construction of SAH-based Bounding
// Volume Hierarchies").
//
// Top-down: each node's primitive centroids are counted into `bin_count` bins
// per axis, a sweep over the bins evaluates the SAH for every bin boundary on
// all three axes, and the primitive references are partitioned in place.
//
// Data layout: every primitive's box is computed once into a 32-byte,
// 32-byte aligned record (lo, triangle index, hi, padding), so binning and
// partitioning load it as two float4 and grow boxes with SSE min/max. A
// node's bins are swept over the non-empty bins only (a boundary inside a run
// of empty bins costs the same as the first one, which is the one chosen),
// found from a bit mask. Scratch arrays are left uninitialised, and large
// ones are asked for transparent huge pages, as their page faults otherwise
// cost about as much as writing them.
//
// Most nodes are small, so their fixed costs matter: a node of two
// primitives needs no bins at all, up to 16 primitives only the bins in use
// are initialised, and up to 64 the partition works from a bit mask of the
// sides instead of a branchy loop. Larger ranges bin odd and even primitives
// into two sets, halving the chains of dependent updates of one bin. All of
// these give exactly the splits, the primitive order and the bounds of the
// plain algorithm.
//
// Parallelism (TBB, through backend/cpu/parallel.h): large nodes bin their
// primitives in parallel, and subtrees above a size threshold are built as
// separate tasks. Tasks allocate child pairs from a shared counter, so the
// first pass lays nodes out in whatever order tasks ran; a second pass copies
// the tree into depth-first order (a node's children pair, then the left
// subtree, then the right). Every decision depends only on the primitives of
// a node, and parallel binning only merges counts and min/max bounds, so the
// output is identical for every thread count.
#include "accel/bvh/builders/binned_sah.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <memory>
#include <type_traits>
#include <vector>

#if defined(__SSE2__) || defined(_M_X64)
#include <immintrin.h>
#define RF_BINNED_SSE 1
#endif

#include "core/huge_pages.h"
#include "backend/cpu/parallel.h"
#include "rayforge/core/memory_budget.h"


namespace rf {
namespace {

constexpr int kMaxBins = 256;
constexpr uint32_t kSmallNodeSize = 16;               // prims per node to initialise only the bins in use
constexpr uint32_t kSmallPartitionSize = 64;          // prims per node to partition by bit mask (at most 64)
constexpr uint32_t kTwoSetBinningSize = 256;          // prims per range to bin into two sets
constexpr uint32_t kParallelBinningSize = 64 * 1024;  // prims per node to bin in parallel
constexpr uint32_t kParallelSubtreeSize = 1024;       // prims per node to spawn child tasks
constexpr uint32_t kParallelCopySize = 4096;          // nodes per subtree to copy in parallel
constexpr uint32_t kGrainSize = 16 * 1024;

// Four floats: SSE where available, else plain arrays with the same
// semantics. min(a, b) and max(a, b) are std::min(a, b) and std::max(a, b)
// lane by lane (b < a ? b : a and a < b ? b : a), so results match scalar
// code bit for bit, signed zeros included.
#if RF_BINNED_SSE
struct F4 {
    __m128 v;
};
inline F4 load4(const float* p) { return {_mm_load_ps(p)}; }  // 16-byte aligned
inline void store4(float* p, F4 a) { _mm_store_ps(p, a.v); }
inline F4 set4(float x, float y, float z, float w) { return {_mm_setr_ps(x, y, z, w)}; }
inline F4 splat4(float x) { return {_mm_set1_ps(x)}; }
inline F4 operator+(F4 a, F4 b) { return {_mm_add_ps(a.v, b.v)}; }
inline F4 operator-(F4 a, F4 b) { return {_mm_sub_ps(a.v, b.v)}; }
inline F4 operator*(F4 a, F4 b) { return {_mm_mul_ps(a.v, b.v)}; }
inline F4 min4(F4 a, F4 b) { return {_mm_min_ps(b.v, a.v)}; }
inline F4 max4(F4 a, F4 b) { return {_mm_max_ps(b.v, a.v)}; }
// Lane 3 cleared: it may hold integer bits (denormals, which slow arithmetic down).
inline F4 xyz0(F4 a) { return {_mm_and_ps(a.v, _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0)))}; }
// Bin indices: x > 0 ? x : 0 (NaN to 0), then x < last ? x : last, truncated.
inline void bin_indices(F4 x, F4 last, int32_t* out) {
    x.v = _mm_max_ps(x.v, _mm_setzero_ps());
    x.v = _mm_min_ps(x.v, last.v);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out), _mm_cvttps_epi32(x.v));
}
// Bit i set where the bin index (as above) in lane i is below `bin`.
inline int bins_below(F4 x, F4 last, int bin) {
    x.v = _mm_max_ps(x.v, _mm_setzero_ps());
    x.v = _mm_min_ps(x.v, last.v);
    const __m128i below = _mm_cmplt_epi32(_mm_cvttps_epi32(x.v), _mm_set1_epi32(bin));
    return _mm_movemask_ps(_mm_castsi128_ps(below));
}
#else
struct F4 {
    float v[4];
};
inline F4 load4(const float* p) { return {{p[0], p[1], p[2], p[3]}}; }
inline void store4(float* p, F4 a) { for (int i = 0; i < 4; ++i) p[i] = a.v[i]; }
inline F4 set4(float x, float y, float z, float w) { return {{x, y, z, w}}; }
inline F4 splat4(float x) { return {{x, x, x, x}}; }
#define RF_BINNED_OP(op)                                               \
    inline F4 operator op(F4 a, F4 b) {                                \
        F4 r;                                                          \
        for (int i = 0; i < 4; ++i) r.v[i] = a.v[i] op b.v[i];         \
        return r;                                                      \
    }
RF_BINNED_OP(+)
RF_BINNED_OP(-)
RF_BINNED_OP(*)
#undef RF_BINNED_OP
inline F4 min4(F4 a, F4 b) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = std::min(a.v[i], b.v[i]);
    return r;
}
inline F4 max4(F4 a, F4 b) {
    F4 r;
    for (int i = 0; i < 4; ++i) r.v[i] = std::max(a.v[i], b.v[i]);
    return r;
}
inline F4 xyz0(F4 a) { return {{a.v[0], a.v[1], a.v[2], 0.0f}}; }
inline void bin_indices(F4 x, F4 last, int32_t* out) {
    for (int i = 0; i < 4; ++i) {
        float t = x.v[i] > 0.0f ? x.v[i] : 0.0f;
        t = t < last.v[i] ? t : last.v[i];
        out[i] = static_cast<int32_t>(t);
    }
}
inline int bins_below(F4 x, F4 last, int bin) {
    int32_t b[4];
    bin_indices(x, last, b);
    return (b[0] < bin ? 1 : 0) | (b[1] < bin ? 2 : 0) | (b[2] < bin ? 4 : 0) | (b[3] < bin ? 8 : 0);
}
#endif

inline Box3f to_box(F4 lo, F4 hi) {
    alignas(16) float l[4], h[4];
    store4(l, lo);
    store4(h, hi);
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
    [[nodiscard]] F4 lo4() const { return load4(lo); }  // lane 3 holds the id: no arithmetic on it
    [[nodiscard]] F4 hi4() const { return load4(hi); }
    [[nodiscard]] F4 centroid4() const { return (xyz0(lo4()) + xyz0(hi4())) * splat4(0.5f); }
};
static_assert(sizeof(PrimRef) == 32 && std::is_trivially_default_constructible_v<PrimRef>);

// A node in allocation order; same layout as BvhNode, but plain data.
struct ScratchNode {
    float lo[3], hi[3];
    uint32_t first, count;
    [[nodiscard]] bool is_leaf() const { return count != 0; }
    [[nodiscard]] BvhNode to_node() const { return {{{lo[0], lo[1], lo[2]}, {hi[0], hi[1], hi[2]}}, first, count}; }
};
static_assert(sizeof(ScratchNode) == 32 && std::is_trivially_default_constructible_v<ScratchNode>);

// Uninitialised array of plain data (budget-checked), hinted for huge pages when large.
template <class T>
std::unique_ptr<T[]> scratch_array(size_t count, std::string_view what) {
    checked_array_bytes(what, count, sizeof(T));
    std::unique_ptr<T[]> a(new T[count]);
    hint_huge_pages(a.get(), count * sizeof(T));
    return a;
}

// Bounds of a set of primitives and of their centroids (lane 3 unused).
struct RangeBounds {
    F4 lo = splat4(FLT_MAX), hi = splat4(-FLT_MAX);
    F4 clo = splat4(FLT_MAX), chi = splat4(-FLT_MAX);
    void add(const PrimRef& p) { add(p.lo4(), p.hi4()); }
    // A primitive by its bounds as loaded by PrimRef::lo4 and hi4.
    void add(F4 l, F4 h) {
        lo = min4(lo, l);
        hi = max4(hi, h);
        const F4 c = (xyz0(l) + xyz0(h)) * splat4(0.5f);  // PrimRef::centroid4
        clo = min4(clo, c);
        chi = max4(chi, c);
    }
    void add(const RangeBounds& o) {
        lo = min4(lo, o.lo);
        hi = max4(hi, o.hi);
        clo = min4(clo, o.clo);
        chi = max4(chi, o.chi);
    }
    [[nodiscard]] Box3f bounds() const { return to_box(lo, hi); }
    [[nodiscard]] Box3f centroids() const { return to_box(clo, chi); }
};

// Maps centroids to bins along each axis of a node's centroid bounds.
struct BinMapping {
    F4 origin;
    F4 scale;  // bins per unit length; 0 on axes where all centroids coincide
    F4 last;   // bin_count - 1
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
        origin = set4(centroids.lo.x, centroids.lo.y, centroids.lo.z, 0.0f);
        scale = set4(s[0], s[1], s[2], 0.0f);
        last = splat4(static_cast<float>(bins - 1));
    }
    // Bin of the centroid of p on each axis.
    void indices(const PrimRef& p, int32_t* out) const {
        const F4 c = p.centroid4();
        bin_indices((c - origin) * scale, last, out);
    }
    // Whether the bin of p's centroid on `axis` is below `bin` (no round
    // trip through memory, for partitioning).
    [[nodiscard]] bool below(const PrimRef& p, int axis, int bin) const {
        const F4 c = p.centroid4();
        return ((bins_below((c - origin) * scale, last, bin) >> axis) & 1) != 0;
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
                store4(lo(axis, i), splat4(FLT_MAX));
                store4(hi(axis, i), splat4(-FLT_MAX));
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
        const F4 l = p.lo4(), h = p.hi4();
        for (int axis = 0; axis < 3; ++axis) {
            const int b = bin[axis];
            store4(lo(axis, b), min4(load4(lo(axis, b)), l));
            store4(hi(axis, b), max4(load4(hi(axis, b)), h));
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
            const F4 l = prims[k].lo4(), h = prims[k].hi4();
            for (int axis = 0; axis < 3; ++axis) {
                const int b = bins[k][axis];
                store4(lo(axis, b), l);
                store4(hi(axis, b), h);
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
                store4(lo(axis, i), min4(load4(lo(axis, i)), load4(o.lo(axis, i))));
                store4(hi(axis, i), max4(load4(hi(axis, i)), load4(o.hi(axis, i))));
                count(axis, i) += o.count(axis, i);
            }
        }
    }
};
static_assert(kMaxBins % 64 == 0);

// Box3f::surface_area of a non-empty box, 2 * (x * y + y * z + z * x) in
// the same order of operations, so the result is the same bit for bit.
inline float surface_area(F4 lo, F4 hi) {
#if RF_BINNED_SSE
    const __m128 e = _mm_sub_ps(xyz0(hi).v, xyz0(lo).v);
    const __m128 p = _mm_mul_ps(e, _mm_shuffle_ps(e, e, _MM_SHUFFLE(3, 0, 2, 1)));  // xy, yz, zx
    const __m128 s = _mm_add_ss(p, _mm_shuffle_ps(p, p, _MM_SHUFFLE(3, 2, 1, 1)));
    return 2.0f * _mm_cvtss_f32(_mm_add_ss(s, _mm_movehl_ps(p, p)));
#else
    return to_box(lo, hi).surface_area();
#endif
}

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
    BinnedSahBuilder(std::span<const Triangle> triangles, const BvhBuildConfig& config, const BinnedSahOptions& binned)
        : triangles_(triangles),
          bin_count_(binned.bin_count),
          max_leaf_size_(static_cast<uint32_t>(config.max_leaf_size)),
          traversal_cost_(config.sah.traversal),
          intersection_cost_(config.sah.intersection) {}

    Bvh build() {
        Bvh bvh;
        const uint32_t count = checked_index_count("BVH primitive count", triangles_.size());
        if (count == 0) return bvh;
        refs_ = scratch_array<PrimRef>(count, "BVH build: primitive references");
        const RangeBounds root = make_prim_refs(count);

        // At most 2n - 1 nodes: every leaf holds at least one primitive.
        const size_t max_nodes = 2 * size_t{count} - 1;
        scratch_ = scratch_array<ScratchNode>(max_nodes, "BVH build: scratch nodes");
        subtree_size_ = scratch_array<uint32_t>(max_nodes, "BVH build: subtree sizes");
        next_node_.store(1, std::memory_order_relaxed);
        build_node(0, 0, count, root, 0);

        const uint32_t node_count = subtree_size_[0];
        parallel::invoke(
            [&] {
                checked_array_bytes("BVH nodes", node_count, sizeof(BvhNode));
                bvh.nodes.reserve(node_count);
                hint_huge_pages(bvh.nodes.data(), size_t{node_count} * sizeof(BvhNode));
                bvh.nodes.resize(node_count);
                bvh.nodes[0] = scratch_[0].to_node();
                copy_descendants(bvh.nodes, 0, 0, 1);
            },
            [&] {
                budgeted_resize(bvh.prim_indices, count, "BVH primitive indices");
                parallel::for_range(0u, count, kGrainSize, [&](uint32_t lo, uint32_t hi) {
                    for (uint32_t i = lo; i != hi; ++i) bvh.prim_indices[i] = refs_[i].id;
                });
            });
        return bvh;
    }

private:

    RangeBounds make_prim_refs(uint32_t count) {
        return parallel::reduce(
            0u, count, kGrainSize, RangeBounds{},
            [&](uint32_t lo, uint32_t hi, RangeBounds acc) {
                for (uint32_t i = lo; i != hi; ++i) {
                    const Triangle& t = triangles_[i];
                    const Vec3f l = vmin(t.v0, vmin(t.v1, t.v2)), h = vmax(t.v0, vmax(t.v1, t.v2));
                    refs_[i] = PrimRef{{l.x, l.y, l.z}, i, {h.x, h.y, h.z}, 0};
                    acc.add(refs_[i]);
                }
                return acc;
            },
            [](RangeBounds a, const RangeBounds& b) { a.add(b); return a; });
    }

    static Vec3f vmin(const Vec3f& a, const Vec3f& b) {
        return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
    }
    static Vec3f vmax(const Vec3f& a, const Vec3f& b) {
        return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
    }

    // Builds the subtree of scratch_[node] over refs_[begin, end); returns its node count.
    uint32_t build_node(uint32_t node, uint32_t begin, uint32_t end, const RangeBounds& range, int depth) {
        const uint32_t count = end - begin;
        ScratchNode& out = scratch_[node];
        const Box3f bounds = range.bounds();
        out.lo[0] = bounds.lo.x; out.lo[1] = bounds.lo.y; out.lo[2] = bounds.lo.z;
        out.hi[0] = bounds.hi.x; out.hi[1] = bounds.hi.y; out.hi[2] = bounds.hi.z;
        if (count <= 1) return make_leaf(node, begin, count);

        const Box3f centroids = range.centroids();
        const float area = bounds.surface_area();
        const BinMapping map(centroids, bin_count_);
        Split split = find_split(begin, end, map);
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
        const uint32_t mid = split.valid() ? partition_by_bin(begin, end, map, split, left, right)
                                           : partition_by_median(begin, end, centroids, left, right);

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
    Split find_split(uint32_t begin, uint32_t end, const BinMapping& map) const {
        Split best;
        if (!map.usable[0] && !map.usable[1] && !map.usable[2]) return best;
        if (end - begin == 2) return find_split_pair(begin, map);
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

    // find_split for two primitives: every axis that puts them into
    // different bins splits them apart at the same cost (the same two boxes,
    // and float addition commutes), so the first such axis is the one the
    // sweep keeps, at the boundary after the lower bin.
    Split find_split_pair(uint32_t begin, const BinMapping& map) const {
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
        F4 lo = splat4(FLT_MAX), hi = splat4(-FLT_MAX);
        uint32_t n = 0;
        for (int t = m - 1; t > 0; --t) {
            const int i = used[t];
            lo = min4(lo, load4(set.lo(axis, i)));
            hi = max4(hi, load4(set.hi(axis, i)));
            n += set.count(axis, i);
            right_area[t] = surface_area(lo, hi);
            right_count[t] = n;
        }
        // Prefix sweep: evaluate the boundary after each used bin but the last.
        lo = splat4(FLT_MAX);
        hi = splat4(-FLT_MAX);
        n = 0;
        for (int t = 0; t + 1 < m; ++t) {
            const int i = used[t];
            lo = min4(lo, load4(set.lo(axis, i)));
            hi = max4(hi, load4(set.hi(axis, i)));
            n += set.count(axis, i);
            const float cost = surface_area(lo, hi) * static_cast<float>(n) +
                               right_area[t + 1] * static_cast<float>(right_count[t + 1]);
            if (!best.valid() || cost < best.cost) best = Split{axis, i + 1, cost, n};  // even when costs overflow
        }
    }

    // Hoare partition of refs_[begin, end) by the split; fills both sides' bounds.
    uint32_t partition_by_bin(uint32_t begin, uint32_t end, const BinMapping& map, const Split& split,
                              RangeBounds& left, RangeBounds& right) {
        if (end - begin <= kSmallPartitionSize) return partition_small(begin, end, map, split, left, right);
        auto goes_left = [&](const PrimRef& p) { return map.below(p, split.axis, split.bin); };
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
            const F4 a_lo = a.lo4(), a_hi = a.hi4(), b_lo = b.lo4(), b_hi = b.hi4();
            store4(a.lo, b_lo);  // lane 3: the id
            store4(a.hi, b_hi);
            store4(b.lo, a_lo);
            store4(b.hi, a_hi);
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
        uint64_t goes_left = 0;
        for (uint32_t k = 0; k < n; ++k) {
            goes_left |= uint64_t{map.below(refs[k], split.axis, split.bin)} << k;
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

    // Writes the descendants of scratch_[from] (copied to out[at]) into
    // out[base, base + subtree size - 1): children pair first, then the left
    // subtree's descendants, then the right's.
    void copy_descendants(std::vector<BvhNode>& out, uint32_t from, uint32_t at, uint32_t base) const {
        const ScratchNode& node = scratch_[from];
        if (node.is_leaf()) return;
        const uint32_t left = node.first;
        out[at].first = base;
        out[base] = scratch_[left].to_node();
        out[base + 1] = scratch_[left + 1].to_node();
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

    std::unique_ptr<PrimRef[]> refs_;
    std::unique_ptr<ScratchNode[]> scratch_;   // nodes in allocation order
    std::unique_ptr<uint32_t[]> subtree_size_;  // per scratch node: nodes in its subtree
    std::atomic<uint32_t> next_node_{1};
};

}  // namespace

Bvh build_binned_sah(std::span<const Triangle> triangles, const BvhBuildConfig& config,
                     const BinnedSahOptions& binned) {
    BinnedSahBuilder builder(triangles, config, binned);
    return builder.build();
}

}  // namespace rf
