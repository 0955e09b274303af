// The per-reference and per-task steps of GridBvh / GridBvhSplit (Garanzha
// 2014, dissertation ch. 4), shared by the CPU builder (grid_bvh.cpp,
// grid_bvh_sparse_grid.cpp, grid_bvh_partial_triangles.cpp) and the CUDA
// builder (backend/cuda/grid_bvh_build.cu), so both build the same tree:
//  - §4.4 partial triangles: the split request of a reference (formula 4.1),
//    its share of the free slots, and its parts (clipped boxes);
//  - §4.2 the 30-bit Grid0 key of a reference and a raw-pointer view of the
//    sparse grid (TopGrid0, the 8^3 bottom grids, the count-only levels)
//    with its cell counts and cell visits;
//  - §4.3 Algorithm 4.1 one split task: refinement to finer levels, the
//    8-bin integer-box SAH over up to 7 planes per axis with the CPU's tie
//    rules, the children's tight IBBs.
// Products that feed sums are rounded separately on the device (no FMA
// contraction), so host and device agree bit for bit.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/rounded_arithmetic.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::gridbvh {

inline constexpr int kFineRes = 1024;  // Grid0 cells per axis (30-bit cell keys)
inline constexpr int kTopRes = 128;    // TopGrid0 cells per axis (high 21 bits of a key)
inline constexpr int kSubRes = 8;      // bottom grid cells per axis (low 9 bits)
inline constexpr int kSubCells = kSubRes * kSubRes * kSubRes;
inline constexpr int kMaskWords = kSubCells / 64;  // 64-bit occupancy words per bottom grid
inline constexpr int kLevels = 8;      // Grid0 (1024^3) .. Grid7 (8^3 = MaxUseRes)
inline constexpr int kMaxUseRes = 8;   // SAH window: 8 bins, 7 planes per axis
inline constexpr uint32_t kEmptyCell = 0xffffffffu;     // TopGrid0: no bottom grid
inline constexpr uint32_t kInvalidRef = 0xffffffffu;    // a part that came out empty
inline constexpr uint32_t kMaxSplitsPerRef = 4096;      // far above 128 parts: only bounds the arithmetic
inline constexpr uint32_t kLeafBit = 0x80000000u;       // hierarchy node: kLeafBit | leaf index

// Exact arithmetic (one rounding per operation): core/rounded_arithmetic.h.
// std::min / std::max semantics (the CPU builder's), not fminf/fmaxf.
RF_HDI float min_f(float a, float b) { return b < a ? b : a; }
RF_HDI float max_f(float a, float b) { return a < b ? b : a; }
RF_HDI int min_i(int a, int b) { return b < a ? b : a; }
RF_HDI int max_i(int a, int b) { return a < b ? b : a; }
RF_HDI Vec3f vmin(const Vec3f& a, const Vec3f& b) { return {min_f(a.x, b.x), min_f(a.y, b.y), min_f(a.z, b.z)}; }
RF_HDI Vec3f vmax(const Vec3f& a, const Vec3f& b) { return {max_f(a.x, b.x), max_f(a.y, b.y), max_f(a.z, b.z)}; }
RF_HDI int popcount64(uint64_t v) {
#if defined(__CUDA_ARCH__)
    return __popcll(v);
#else
    return __builtin_popcountll(v);
#endif
}
RF_HDI int lowest_bit64(uint64_t v) {  // v != 0
#if defined(__CUDA_ARCH__)
    return __ffsll(static_cast<long long>(v)) - 1;
#else
    return __builtin_ctzll(v);
#endif
}

// A reference: a whole triangle or a partial triangle (triangle index plus
// the box of its part). 32 bytes so passes stream through memory.
struct GridRef {
    Vec3f lo;
    uint32_t prim;
    Vec3f hi;
    uint32_t unused;
    [[nodiscard]] RF_HDI Box3f bounds() const { return {lo, hi}; }
    [[nodiscard]] RF_HDI Vec3f centroid() const { return (lo + hi) * 0.5f; }
};

// Maps world space to Grid0 cells over the scene box; the cells are not
// cubic (1024 per axis of the box), and an axis of zero extent has one cell.
struct GridFrame {
    Vec3f origin;
    Vec3f extent;
    Vec3f to_cell;  // Grid0 cells per unit length; 0 on axes of zero extent

    GridFrame() = default;
    explicit GridFrame(const Box3f& scene);  // host: grid_bvh_sparse_grid.cpp
    [[nodiscard]] RF_HDI int cell(float x, int axis) const {
        float c = (x - origin[axis]) * to_cell[axis];
        c = c > 0.0f ? c : 0.0f;  // also maps NaN to 0
        c = c < float(kFineRes - 1) ? c : float(kFineRes - 1);
        return int(c);
    }
    // World position of the Grid0 plane `index` (0..1024) on `axis`.
    [[nodiscard]] RF_HDI float plane(int index, int axis) const {
        return index >= kFineRes ? add_rn(origin[axis], extent[axis])
                                 : add_rn(origin[axis], mul_rn(extent[axis], float(index) / float(kFineRes)));
    }
    // Cell edge lengths at a level (Grid_level has 1024 >> level cells per axis).
    [[nodiscard]] RF_HDI Vec3f cell_size(int level) const { return extent * (float(1 << level) / float(kFineRes)); }
};

// An integer box of cells at one level, bounds inclusive.
struct CellBox {
    uint16_t lo[3];
    uint16_t hi[3];
    [[nodiscard]] RF_HDI int extent(int axis) const { return int(hi[axis]) - int(lo[axis]) + 1; }
};

// ---- §4.2: cell keys ----

// Interleaves the low 3 bits of x, y, z (x lowest).
RF_HDI uint32_t morton9(uint32_t x, uint32_t y, uint32_t z) {
    uint32_t code = 0;
    for (int bit = 0; bit < 3; ++bit) {
        code |= ((x >> bit) & 1u) << (3 * bit);
        code |= ((y >> bit) & 1u) << (3 * bit + 1);
        code |= ((z >> bit) & 1u) << (3 * bit + 2);
    }
    return code;
}

// Bottom-grid Morton key -> coordinates within the 8^3 bottom grid.
RF_HDI void morton9_decode(uint32_t key, int& x, int& y, int& z) {
    x = y = z = 0;
    for (int bit = 0; bit < 3; ++bit) {
        x |= int((key >> (3 * bit)) & 1u) << bit;
        y |= int((key >> (3 * bit + 1)) & 1u) << bit;
        z |= int((key >> (3 * bit + 2)) & 1u) << bit;
    }
}

// 30-bit Grid0 key of the cell holding `c`: top cell in the high 21 bits
// (linear), cell within the 8^3 bottom grid in the low 9 bits (Morton order,
// so every cell of Grid1 and Grid2 is a run of consecutive keys).
RF_HDI uint32_t fine_key(const GridFrame& frame, const Vec3f& c) {
    const uint32_t x = uint32_t(frame.cell(c.x, 0)), y = uint32_t(frame.cell(c.y, 1)), z = uint32_t(frame.cell(c.z, 2));
    const uint32_t top = (x >> 3) + kTopRes * ((y >> 3) + kTopRes * (z >> 3));
    return (top << 9) | morton9(x & 7, y & 7, z & 7);
}

// ---- §4.4: partial triangles ----

RF_HDI GridRef triangle_ref(const Triangle& t, uint32_t index) {
    return GridRef{vmin(t.v0, vmin(t.v1, t.v2)), index, vmax(t.v0, vmax(t.v1, t.v2)), 0};
}

// reqSplits = floor(longest extent / triangleMaxWidth), capped (pass 1 and 2 alike).
RF_HDI uint32_t split_request(const GridRef& ref, float max_width) {
    const Vec3f e = ref.hi - ref.lo;
    const float widest = max_f(e.x, max_f(e.y, e.z));
    const float req = floorf(widest / max_width);
    return req >= 1.0f ? uint32_t(min_f(req, float(kMaxSplitsPerRef))) : 0u;
}

// A reference's splits when `asked` splits in all compete for `available`
// slots: all it asked, or floor(request * available / asked). The product
// fits 64 bits: when asked > available, available < asked <= 4096 * 2^32.
RF_HDI uint32_t split_share(uint32_t request, uint64_t asked, uint64_t available) {
    if (asked <= available) return request;
    return uint32_t(uint64_t(request) * available / asked);
}

// Box of the part of `tri` inside `region`: the triangle clipped as a polygon
// (Sutherland-Hodgman) against the region's six planes. Empty when they do
// not meet. The result lies inside `region` and inside the triangle's box.
RF_HDI Box3f clip_triangle_to_box(const Triangle& tri, const Box3f& region) {
    Vec3f poly[12] = {tri.v0, tri.v1, tri.v2};  // each plane adds at most one vertex (3 + 6 = 9)
    Vec3f next[12];
    int count = 3;
    for (int axis = 0; axis < 3 && count > 0; ++axis) {
        for (int side = 0; side < 2 && count > 0; ++side) {
            const float plane = side == 0 ? region.lo[axis] : region.hi[axis];
            int out = 0;
            for (int i = 0; i < count; ++i) {
                const Vec3f a = poly[i];
                const Vec3f b = poly[(i + 1) % count];
                const bool in_a = side == 0 ? a[axis] >= plane : a[axis] <= plane;
                const bool in_b = side == 0 ? b[axis] >= plane : b[axis] <= plane;
                if (in_a) next[out++] = a;
                if (in_a != in_b) {
                    const float t = (plane - a[axis]) / (b[axis] - a[axis]);
                    Vec3f v(add_rn(a.x, mul_rn(b.x - a.x, t)), add_rn(a.y, mul_rn(b.y - a.y, t)),
                            add_rn(a.z, mul_rn(b.z - a.z, t)));
                    v[axis] = plane;  // exactly on the plane, so parts meet without gaps
                    next[out++] = v;
                }
            }
            count = out;
            for (int i = 0; i < count; ++i) poly[i] = next[i];
        }
    }
    Box3f box;
    if (count == 0) return box;
    for (int i = 0; i < count; ++i) box = {vmin(box.lo, poly[i]), vmax(box.hi, poly[i])};
    // Interpolated coordinates may be a few ulps inside the true part; grow
    // slightly so the parts still cover the whole triangle, then clamp.
    for (int axis = 0; axis < 3; ++axis) {
        const float scale = max_f(fabsf(box.lo[axis]), fabsf(box.hi[axis]));
        const float eps = mul_rn(8.0f * 1.19209290e-7f, scale);  // 8 FLT_EPSILON
        box.lo[axis] -= eps;
        box.hi[axis] += eps;
    }
    const Box3f tri_box{vmin(tri.v0, vmin(tri.v1, tri.v2)), vmax(tri.v0, vmax(tri.v1, tri.v2))};
    box = {vmax(box.lo, region.lo), vmin(box.hi, region.hi)};
    box = {vmax(box.lo, tri_box.lo), vmin(box.hi, tri_box.hi)};
    return box;
}

// Writes the s + 1 parts of `ref` (triangle `tri`) along its longest axis
// into out[0 .. s]; the split planes are the Grid0 planes nearest to equal
// parts. Slots of parts that came out empty (or whose plane collapsed onto
// a neighbour) are marked kInvalidRef; at least one part is kept.
RF_HDI void write_parts(const Triangle& tri, const GridRef& ref, uint32_t splits, const GridFrame& frame, GridRef* out) {
    const Box3f box = ref.bounds();
    const int axis = box.largest_axis();
    const float lo = box.lo[axis], hi = box.hi[axis];
    float previous = lo;
    bool any = false;
    for (uint32_t k = 0; k <= splits; ++k) {
        float next = hi;
        if (k < splits) {
            // The Grid0 plane nearest to the k+1-th equal division.
            const double x = dadd_rn(double(lo), double(hi - lo) * double(k + 1) / double(splits + 1));
            double g = round((x - double(frame.origin[axis])) * double(frame.to_cell[axis]));
            g = g < 0.0 ? 0.0 : (g > double(kFineRes) ? double(kFineRes) : g);
            next = frame.plane(int(g), axis);
            if (!(next > previous && next < hi)) {  // collapsed onto a neighbour: fewer parts
                out[k].prim = kInvalidRef;
                continue;
            }
        }
        Box3f region = box;
        region.lo[axis] = previous;
        region.hi[axis] = next;
        previous = next;
        const Box3f part = clip_triangle_to_box(tri, region);
        if (part.is_empty()) {
            out[k].prim = kInvalidRef;
            continue;
        }
        out[k] = GridRef{part.lo, ref.prim, part.hi, 0};
        any = true;
    }
    if (!any) out[0] = ref;
}

// ---- §4.2: the sparse grid, read through raw pointers ----

// The arrays of a built SparseGrid (see grid_bvh_sparse_grid.h), on either side.
struct SparseGridView {
    const uint32_t* top_index;   // 128^3: rank among the non-empty top cells, or kEmptyCell
    const uint32_t* top_begin;   // per non-empty top cell, plus an end: first sorted position
    const uint32_t* top_cells;   // per non-empty top cell, plus an end: its first non-empty Grid0 cell
    const uint64_t* top_mask;    // kMaskWords per non-empty top cell: occupancy of its 8^3 bottom grid
    const uint32_t* fine_begin;  // per non-empty Grid0 cell, plus an end: first sorted position
    const uint32_t* dense[4];    // Grid4..Grid7 (64^3 .. 8^3) counts
};

RF_HDI uint32_t top_rank(const SparseGridView& g, int tx, int ty, int tz) {
    return g.top_index[uint32_t(tx) + uint32_t(kTopRes) * (uint32_t(ty) + uint32_t(kTopRes) * uint32_t(tz))];
}

// Non-empty bottom-grid cells of top cell m with Morton key below `key`.
RF_HDI uint32_t occupied_below(const SparseGridView& g, uint32_t m, uint32_t key) {
    const uint64_t* words = g.top_mask + size_t{m} * kMaskWords;
    uint32_t r = 0;
    const uint32_t full = key / 64;
    for (uint32_t w = 0; w < full; ++w) r += uint32_t(popcount64(words[w]));
    if (key % 64 != 0) r += uint32_t(popcount64(words[full] & ((uint64_t{1} << (key % 64)) - 1)));
    return r;
}

// Sorted positions [first, end) of the references of bottom-grid keys [key_lo, key_hi) of top cell m.
RF_HDI void sub_range(const SparseGridView& g, uint32_t m, uint32_t key_lo, uint32_t key_hi, uint32_t& first,
                      uint32_t& end) {
    const uint32_t base = g.top_cells[m];
    first = g.fine_begin[base + occupied_below(g, m, key_lo)];
    end = g.fine_begin[base + occupied_below(g, m, key_hi)];
}

// References whose Grid0 cell lies in cell (x, y, z) of Grid_level.
RF_HDI uint32_t cell_count(const SparseGridView& g, int level, int x, int y, int z) {
    if (level >= 4) {
        const int res = kFineRes >> level;
        return g.dense[level - 4][uint32_t(x) + uint32_t(res) * (uint32_t(y) + uint32_t(res) * uint32_t(z))];
    }
    const int shift = 3 - level;
    const uint32_t m = top_rank(g, x >> shift, y >> shift, z >> shift);
    if (m == kEmptyCell) return 0;
    if (level == 3) return g.top_begin[m + 1] - g.top_begin[m];
    // Grid_level cell = 8^level consecutive Morton keys of the bottom grid.
    const uint32_t mask = uint32_t(kSubRes >> level) - 1;
    const uint32_t key =
        morton9((uint32_t(x) & mask) << level, (uint32_t(y) & mask) << level, (uint32_t(z) & mask) << level);
    uint32_t first = 0, end = 0;
    sub_range(g, m, key, key + (1u << (3 * level)), first, end);
    return end - first;
}

// Calls f(x, y, z, n) for the non-empty cells of Grid_level in `box` with
// their reference counts; at Grid0..Grid2 a cell may come in several calls
// (one per non-empty Grid0 cell), whose n add up. The work follows the
// non-empty cells, not the volume of the box. Visitor `slice` of `slices`
// takes every slices-th cell (Grid3 and coarser) or top cell (finer), so
// the visitors of one task together see each cell once.
template <class F>
RF_HDI void for_each_cell(const SparseGridView& g, int level, const CellBox& box, F&& f, int slice = 0,
                          int slices = 1) {
    if (level >= 3) {
        const int ex = box.extent(0), ey = box.extent(1), ez = box.extent(2);
        for (int i = slice; i < ex * ey * ez; i += slices) {
            const int x = box.lo[0] + i % ex, y = box.lo[1] + (i / ex) % ey, z = box.lo[2] + i / (ex * ey);
            if (const uint32_t n = cell_count(g, level, x, y, z)) f(x, y, z, n);
        }
        return;
    }
    // The occupied top cells overlapping the box and their non-empty Grid0 cells.
    const int shift = 3 - level;
    const int tlo[3] = {box.lo[0] >> shift, box.lo[1] >> shift, box.lo[2] >> shift};
    const int tex = (box.hi[0] >> shift) - tlo[0] + 1, tey = (box.hi[1] >> shift) - tlo[1] + 1,
              tez = (box.hi[2] >> shift) - tlo[2] + 1;
    for (int i = slice; i < tex * tey * tez; i += slices) {
        const int tx = tlo[0] + i % tex, ty = tlo[1] + (i / tex) % tey, tz = tlo[2] + i / (tex * tey);
        const uint32_t m = top_rank(g, tx, ty, tz);
        if (m == kEmptyCell) continue;
        uint32_t cell = g.top_cells[m];
        const uint64_t* words = g.top_mask + size_t{m} * kMaskWords;
        for (int w = 0; w < kMaskWords; ++w) {
            for (uint64_t bits = words[w]; bits != 0; bits &= bits - 1, ++cell) {
                int sx, sy, sz;
                morton9_decode(uint32_t(w * 64 + lowest_bit64(bits)), sx, sy, sz);
                const int x = (tx << shift) | (sx >> level), y = (ty << shift) | (sy >> level),
                          z = (tz << shift) | (sz >> level);
                if (x < box.lo[0] || x > box.hi[0] || y < box.lo[1] || y > box.hi[1] || z < box.lo[2] ||
                    z > box.hi[2]) {
                    continue;
                }
                f(x, y, z, g.fine_begin[cell + 1] - g.fine_begin[cell]);
            }
        }
    }
}

// ---- §4.3: split tasks of EmitHierarchy (Algorithm 4.1) ----

struct SplitTask {
    uint32_t node;
    uint32_t count;  // references in the IBB
    CellBox box;     // the IBB, in cells of Grid_level
    uint8_t level;
    uint8_t depth;
};

struct TaskOutcome {
    bool split;
    SplitTask left, right;  // a leaf keeps its (refined) task in `left`
};

// Where a hierarchy node's references lie: its IBB when it was created.
struct NodeRegion {
    CellBox box;
    uint8_t level;
};

// Integer-box statistics of one bin: reference count and the box of its non-empty cells.
struct CellBin {
    uint32_t count;
    int lo[3];
    int hi[3];
    RF_HDI void clear() {
        count = 0;
        for (int a = 0; a < 3; ++a) {
            lo[a] = 1 << 20;
            hi[a] = -1;
        }
    }
    RF_HDI void add(int x, int y, int z, uint32_t c) {
        count += c;
        const int p[3] = {x, y, z};
        for (int a = 0; a < 3; ++a) {
            lo[a] = min_i(lo[a], p[a]);
            hi[a] = max_i(hi[a], p[a]);
        }
    }
    RF_HDI void merge(const CellBin& o) {
        count += o.count;
        for (int a = 0; a < 3; ++a) {
            lo[a] = min_i(lo[a], o.lo[a]);
            hi[a] = max_i(hi[a], o.hi[a]);
        }
    }
    [[nodiscard]] RF_HDI CellBox box() const {
        return {{uint16_t(lo[0]), uint16_t(lo[1]), uint16_t(lo[2])}, {uint16_t(hi[0]), uint16_t(hi[1]), uint16_t(hi[2])}};
    }
};

// The 8 bins per axis of one task: bins[axis][cell - IBB.lo].
struct TaskBins {
    CellBin bins[3][kMaxUseRes];
    RF_HDI void clear() {
        for (int a = 0; a < 3; ++a) {
            for (int b = 0; b < kMaxUseRes; ++b) bins[a][b].clear();
        }
    }
};

// Levels of halving needed until `count` references fit in leaves of `leaf_size`.
RF_HDI int median_levels(uint32_t count, uint32_t leaf_size) {
    const uint32_t leaves = (count + leaf_size - 1) / leaf_size;
    if (leaves <= 1) return 0;
    int bits = 0;
    for (uint32_t v = leaves - 1; v != 0; v >>= 1) ++bits;  // bit_width(leaves - 1)
    return bits;
}

// One visitor's share of a scan: adds the non-empty cells of `box` at `level` to the bins.
RF_HDI void bin_cells(const SparseGridView& g, int level, const CellBox& box, TaskBins& b, int slice = 0,
                      int slices = 1) {
    for_each_cell(
        g, level, box,
        [&](int x, int y, int z, uint32_t c) {
            b.bins[0][x - box.lo[0]].add(x, y, z, c);
            b.bins[1][y - box.lo[1]].add(x, y, z, c);
            b.bins[2][z - box.lo[2]].add(x, y, z, c);
        },
        slice, slices);
}

// Surface area (half) of a bin's cells at the task's cell size.
RF_HDI double bin_area(const CellBin& b, const Vec3f& cell) {
    const double ex = dmul_rn(double(b.hi[0] - b.lo[0] + 1), cell.x);
    const double ey = dmul_rn(double(b.hi[1] - b.lo[1] + 1), cell.y);
    const double ez = dmul_rn(double(b.hi[2] - b.lo[2] + 1), cell.z);
    return dadd_rn(dadd_rn(dmul_rn(ex, ey), dmul_rn(ey, ez)), dmul_rn(ez, ex));
}

// One split task (Fig. 4.3): refine while the IBB is small, bin its
// non-empty cells, pick the cheapest of up to 7 planes per axis (the first
// strictly cheapest in axis-then-plane order). `scan(level, box, bins)`
// fills `bins` (cleared by it) with all non-empty cells of `box`: one thread
// on the CPU, the task's 8 threads on the device.
template <class Scan>
RF_HDI TaskOutcome process_task(SplitTask task, uint32_t max_leaf_size, const GridFrame& frame, Scan&& scan) {
    TaskOutcome outcome;
    outcome.split = false;
    outcome.left = task;
    outcome.right = task;
    if (task.count <= max_leaf_size) return outcome;
    TaskBins bins;
    CellBox scanned{};  // the box the bins were filled over (bins index from its lo)
    for (;;) {
        const int longest = max_i(task.box.extent(0), max_i(task.box.extent(1), task.box.extent(2)));
        if (task.level > 0 && longest <= kMaxUseRes / 2) {
            for (int a = 0; a < 3; ++a) {
                task.box.lo[a] = uint16_t(2 * task.box.lo[a]);
                task.box.hi[a] = uint16_t(2 * task.box.hi[a] + 1);
            }
            --task.level;
            continue;
        }
        scan(int(task.level), task.box, bins);
        scanned = task.box;
        // Tighten the IBB to its non-empty cells; refine again if it shrank enough.
        CellBin all;
        all.clear();
        for (int b = 0; b < kMaxUseRes; ++b) all.merge(bins.bins[0][b]);
        const CellBox tight = all.box();
        bool shrunk = false;
        for (int a = 0; a < 3; ++a) shrunk |= tight.lo[a] != task.box.lo[a] || tight.hi[a] != task.box.hi[a];
        task.box = tight;
        if (shrunk && task.level > 0 && max_i(tight.extent(0), max_i(tight.extent(1), tight.extent(2))) <= kMaxUseRes / 2) {
            continue;
        }
        break;
    }
    outcome.left = task;
    const Vec3f cell = frame.cell_size(task.level);
    int best_axis = -1;
    double best_cost = 0.0;
    CellBin best_left, best_right;
    for (int a = 0; a < 3; ++a) {
        const int bins_used = scanned.extent(a);
        if (bins_used < 2) continue;
        CellBin right_acc[kMaxUseRes];
        CellBin acc;
        acc.clear();
        for (int i = bins_used - 1; i > 0; --i) {
            acc.merge(bins.bins[a][i]);
            right_acc[i] = acc;
        }
        CellBin left;
        left.clear();
        for (int i = 1; i < bins_used; ++i) {
            left.merge(bins.bins[a][i - 1]);
            const CellBin& right = right_acc[i];
            if (left.count == 0 || right.count == 0) continue;
            const double cost =
                dadd_rn(dmul_rn(bin_area(left, cell), double(left.count)), dmul_rn(bin_area(right, cell), double(right.count)));
            if (best_axis < 0 || cost < best_cost) {
                best_axis = a;
                best_cost = cost;
                best_left = left;
                best_right = right;
            }
        }
    }
    if (best_axis < 0) return outcome;  // one Grid0 cell: a leaf
    const uint32_t larger = best_left.count > best_right.count ? best_left.count : best_right.count;
    if (task.depth + 1 + median_levels(larger, max_leaf_size) > kBvhMaxDepth) return outcome;
    outcome.split = true;
    outcome.left = SplitTask{task.node, best_left.count, best_left.box(), task.level, uint8_t(task.depth + 1)};
    outcome.right = SplitTask{0, best_right.count, best_right.box(), task.level, uint8_t(task.depth + 1)};
    return outcome;
}

// The single-thread scan of the CPU builder.
struct SerialScan {
    const SparseGridView* grid;
    RF_HDI void operator()(int level, const CellBox& box, TaskBins& bins) const {
        bins.clear();
        bin_cells(*grid, level, box, bins);
    }
};

// The leaf of a reference (the reference shuffling of §4.3, "applied at leaf
// generation"): descend the hierarchy with the reference's Grid0 cell; the
// left child's IBB decides (sibling IBBs are disjoint).
RF_HDI uint32_t leaf_of_reference(const uint32_t* hnodes, const NodeRegion* regions, const GridFrame& frame,
                                  const GridRef& ref) {
    const Vec3f c = ref.centroid();
    const int cell[3] = {frame.cell(c.x, 0), frame.cell(c.y, 1), frame.cell(c.z, 2)};
    uint32_t h = 0;
    while (!(hnodes[h] & kLeafBit)) {
        const uint32_t left = hnodes[h];
        const NodeRegion& r = regions[left];
        bool inside = true;
        for (int a = 0; a < 3; ++a) {
            const int v = cell[a] >> r.level;
            inside &= v >= r.box.lo[a] && v <= r.box.hi[a];
        }
        h = inside ? left : left + 1;
    }
    return hnodes[h] & ~kLeafBit;
}

// The root task: the whole Grid7 (8^3) with every reference.
RF_HDI SplitTask root_task(uint32_t references) {
    const uint16_t top_max = uint16_t((kFineRes >> (kLevels - 1)) - 1);
    return SplitTask{0, references, {{0, 0, 0}, {top_max, top_max, top_max}}, uint8_t(kLevels - 1), 0};
}

}  // namespace rf::gridbvh
