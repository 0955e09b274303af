// The sparse hierarchical grid of GridBvh (Garanzha 2014, dissertation §4.2):
// Grid0 at 1024^3 stored as TopGrid0 (128^3) with one 8^3 bottom grid per
// non-empty top cell, plus count-only levels of detail down to 8^3. The
// references, cells and keys are the shared steps of grid_bvh_steps.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "accel/bvh/builders/grid_bvh_steps.h"
#include "rayforge/math/box.h"

namespace rf::gridbvh {

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
    [[nodiscard]] uint32_t count(int level, int x, int y, int z) const { return cell_count(view(), level, x, y, z); }
    // Calls f(x, y, z, n) for the non-empty cells of Grid_level in `box`
    // with their reference counts; at Grid0..Grid2 a cell may come in
    // several calls (one per non-empty Grid0 cell), whose n add up. The work
    // follows the non-empty cells, not the volume of the box.
    template <class F>
    void for_each_cell(int level, const CellBox& box, F&& f) const {
        gridbvh::for_each_cell(view(), level, box, f);
    }
    // Appends the positions in sorted_refs() of the references in `box` of Grid_level.
    void collect(int level, const CellBox& box, std::vector<uint32_t>& out) const;

    // Reference indices sorted by Grid0 key (ties in reference order).
    [[nodiscard]] std::span<const uint32_t> sorted_refs() const { return sorted_; }
    [[nodiscard]] size_t occupied_top_cells() const { return top_key_.size(); }
    [[nodiscard]] size_t occupied_fine_cells() const { return fine_begin_.empty() ? 0 : fine_begin_.size() - 1; }
    [[nodiscard]] size_t memory_bytes() const;

    // The arrays through raw pointers (the shared steps read them so).
    [[nodiscard]] SparseGridView view() const {
        return {top_index_.data(), top_begin_.data(), top_cells_.data(), top_mask_.data(), fine_begin_.data(),
                {dense_[0].data(), dense_[1].data(), dense_[2].data(), dense_[3].data()}};
    }
    // The arrays themselves, for comparing with the device's.
    [[nodiscard]] std::span<const uint32_t> top_index() const { return top_index_; }
    [[nodiscard]] std::span<const uint32_t> top_keys() const { return top_key_; }
    [[nodiscard]] std::span<const uint32_t> top_begin() const { return top_begin_; }
    [[nodiscard]] std::span<const uint32_t> top_cells() const { return top_cells_; }
    [[nodiscard]] std::span<const uint64_t> top_mask() const { return top_mask_; }
    [[nodiscard]] std::span<const uint32_t> fine_begin() const { return fine_begin_; }
    [[nodiscard]] std::span<const uint32_t> dense(int k) const { return dense_[k]; }

private:
    static constexpr uint32_t kEmpty = kEmptyCell;

    std::vector<uint32_t> sorted_;      // reference indices in Grid0 key order
    std::vector<uint32_t> top_index_;   // 128^3: rank among non-empty top cells (bottomGridIDs) or kEmpty
    std::vector<uint32_t> top_key_;     // per non-empty top cell: its 21-bit key
    std::vector<uint32_t> top_begin_;   // per non-empty top cell, plus an end: first sorted position
    std::vector<uint32_t> top_cells_;   // per non-empty top cell, plus an end: its first non-empty Grid0 cell
    std::vector<uint64_t> top_mask_;    // 8 words per non-empty top cell: occupancy of its 8^3 bottom grid
    std::vector<uint32_t> fine_begin_;  // per non-empty Grid0 cell, plus an end: first sorted position
    std::vector<uint32_t> dense_[4];    // Grid4..Grid7 (64^3 .. 8^3), dense counts
};

}  // namespace rf::gridbvh
