// The sparse hierarchical grid of GridBvh (Garanzha 2014, dissertation §4.2):
// Grid0 at 1024^3 stored as TopGrid0 (128^3) with one 8^3 bottom grid per
// non-empty top cell, plus count-only levels of detail down to 8^3.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "rayforge/math/box.h"

namespace rf::gridbvh {

inline constexpr int kFineRes = 1024;  // Grid0 cells per axis (30-bit cell keys)
inline constexpr int kTopRes = 128;    // TopGrid0 cells per axis (high 21 bits of a key)
inline constexpr int kSubRes = 8;      // bottom grid cells per axis (low 9 bits)
inline constexpr int kSubCells = kSubRes * kSubRes * kSubRes;
inline constexpr int kLevels = 8;      // Grid0 (1024^3) .. Grid7 (8^3 = MaxUseRes)
inline constexpr int kMaxUseRes = 8;   // SAH window: 8 bins, 7 planes per axis

// A reference: a whole triangle or a partial triangle (triangle index plus
// the box of its part). 32 bytes so passes stream through memory.
struct GridRef {
    Vec3f lo;
    uint32_t prim;
    Vec3f hi;
    uint32_t unused;
    [[nodiscard]] Box3f bounds() const { return {lo, hi}; }
    [[nodiscard]] Vec3f centroid() const { return (lo + hi) * 0.5f; }
};

// Maps world space to Grid0 cells over the scene box; the cells are not
// cubic (1024 per axis of the box), and an axis of zero extent has one cell.
struct GridFrame {
    Vec3f origin;
    Vec3f extent;
    Vec3f to_cell;  // Grid0 cells per unit length; 0 on axes of zero extent

    explicit GridFrame(const Box3f& scene);
    [[nodiscard]] int cell(float x, int axis) const {
        float c = (x - origin[axis]) * to_cell[axis];
        c = c > 0.0f ? c : 0.0f;  // also maps NaN to 0
        c = c < float(kFineRes - 1) ? c : float(kFineRes - 1);
        return int(c);
    }
    // World position of the Grid0 plane `index` (0..1024) on `axis`.
    [[nodiscard]] float plane(int index, int axis) const {
        return index >= kFineRes ? origin[axis] + extent[axis]
                                 : origin[axis] + extent[axis] * (float(index) / float(kFineRes));
    }
    // Cell edge lengths at a level (Grid_level has 1024 >> level cells per axis).
    [[nodiscard]] Vec3f cell_size(int level) const { return extent * (float(1 << level) / float(kFineRes)); }
};

// An integer box of cells at one level, bounds inclusive.
struct CellBox {
    uint16_t lo[3];
    uint16_t hi[3];
    [[nodiscard]] int extent(int axis) const { return int(hi[axis]) - int(lo[axis]) + 1; }
};

// 30-bit Grid0 key of the cell holding `c`: top cell in the high 21 bits
// (linear), cell within the 8^3 bottom grid in the low 9 bits (Morton order,
// so every cell of Grid1 and Grid2 is a run of consecutive keys).
uint32_t fine_key(const GridFrame& frame, const Vec3f& c);

class SparseGrid {
public:
    struct BuildTimes {
        double sort_ms = 0.0;
        double grid0_ms = 0.0;
        double coarse_ms = 0.0;
    };

    // Bins every reference's box centre into Grid0 (§4.2 steps 1-6).
    void build(std::span<const GridRef> refs, const GridFrame& frame, BuildTimes* times = nullptr);

    // References whose Grid0 cell lies in cell (x, y, z) of Grid_level.
    [[nodiscard]] uint32_t count(int level, int x, int y, int z) const;
    // Calls f(x, y, z, n) for the non-empty cells of Grid_level in `box`
    // with their reference counts; at Grid0..Grid2 a cell may come in
    // several calls (one per non-empty Grid0 cell), whose n add up. The work
    // follows the non-empty cells, not the volume of the box.
    template <class F>
    void for_each_cell(int level, const CellBox& box, F&& f) const;
    // Appends the positions in sorted_refs() of the references in `box` of Grid_level.
    void collect(int level, const CellBox& box, std::vector<uint32_t>& out) const;

    // Reference indices sorted by Grid0 key (ties in reference order).
    [[nodiscard]] std::span<const uint32_t> sorted_refs() const { return sorted_; }
    [[nodiscard]] size_t occupied_top_cells() const { return top_key_.size(); }
    [[nodiscard]] size_t occupied_fine_cells() const { return fine_begin_.empty() ? 0 : fine_begin_.size() - 1; }
    [[nodiscard]] size_t memory_bytes() const;

private:
    static constexpr uint32_t kEmpty = 0xffffffffu;
    [[nodiscard]] uint32_t top_rank(int tx, int ty, int tz) const {
        return top_index_[size_t(tx) + size_t(kTopRes) * (size_t(ty) + size_t(kTopRes) * size_t(tz))];
    }
    // Sorted positions [first, second) of the references of bottom-grid
    // Morton keys [key_lo, key_hi) of non-empty top cell m.
    [[nodiscard]] std::pair<uint32_t, uint32_t> sub_range(uint32_t m, uint32_t key_lo, uint32_t key_hi) const;
    // Non-empty bottom-grid cells of top cell m with Morton key below `key`.
    [[nodiscard]] uint32_t rank(uint32_t m, uint32_t key) const;

    std::vector<uint32_t> sorted_;      // reference indices in Grid0 key order
    std::vector<uint32_t> top_index_;   // 128^3: rank among non-empty top cells (bottomGridIDs) or kEmpty
    std::vector<uint32_t> top_key_;     // per non-empty top cell: its 21-bit key
    std::vector<uint32_t> top_begin_;   // per non-empty top cell, plus an end: first sorted position
    std::vector<uint32_t> top_cells_;   // per non-empty top cell, plus an end: its first non-empty Grid0 cell
    std::vector<uint64_t> top_mask_;    // 8 words per non-empty top cell: occupancy of its 8^3 bottom grid
    std::vector<uint32_t> fine_begin_;  // per non-empty Grid0 cell, plus an end: first sorted position
    std::vector<uint32_t> dense_[4];    // Grid4..Grid7 (64^3 .. 8^3), dense counts
};

// Bottom-grid Morton key -> coordinates within the 8^3 bottom grid.
inline void morton9_decode(uint32_t key, int& x, int& y, int& z) {
    x = y = z = 0;
    for (int bit = 0; bit < 3; ++bit) {
        x |= int((key >> (3 * bit)) & 1u) << bit;
        y |= int((key >> (3 * bit + 1)) & 1u) << bit;
        z |= int((key >> (3 * bit + 2)) & 1u) << bit;
    }
}

template <class F>
void SparseGrid::for_each_cell(int level, const CellBox& box, F&& f) const {
    if (level >= 3) {
        for (int z = box.lo[2]; z <= box.hi[2]; ++z) {
            for (int y = box.lo[1]; y <= box.hi[1]; ++y) {
                for (int x = box.lo[0]; x <= box.hi[0]; ++x) {
                    if (const uint32_t n = count(level, x, y, z)) f(x, y, z, n);
                }
            }
        }
        return;
    }
    // Visit the occupied top cells overlapping the box and their non-empty Grid0 cells.
    const int shift = 3 - level;
    for (int tz = box.lo[2] >> shift; tz <= box.hi[2] >> shift; ++tz) {
        for (int ty = box.lo[1] >> shift; ty <= box.hi[1] >> shift; ++ty) {
            for (int tx = box.lo[0] >> shift; tx <= box.hi[0] >> shift; ++tx) {
                const uint32_t m = top_rank(tx, ty, tz);
                if (m == kEmpty) continue;
                uint32_t cell = top_cells_[m];
                const uint64_t* words = &top_mask_[size_t{m} * (kSubCells / 64)];
                for (int w = 0; w < kSubCells / 64; ++w) {
                    for (uint64_t bits = words[w]; bits != 0; bits &= bits - 1, ++cell) {
                        int sx, sy, sz;
                        morton9_decode(uint32_t(w * 64 + std::countr_zero(bits)), sx, sy, sz);
                        const int x = ((tx << shift) | (sx >> level)), y = ((ty << shift) | (sy >> level)),
                                  z = ((tz << shift) | (sz >> level));
                        if (x < box.lo[0] || x > box.hi[0] || y < box.lo[1] || y > box.hi[1] || z < box.lo[2] ||
                            z > box.hi[2]) {
                            continue;
                        }
                        f(x, y, z, fine_begin_[cell + 1] - fine_begin_[cell]);
                    }
                }
            }
        }
    }
}

}  // namespace rf::gridbvh
