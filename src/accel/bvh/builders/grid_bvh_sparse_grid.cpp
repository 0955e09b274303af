// The sparse hierarchical grid of GridBvh (Garanzha 2014, dissertation §4.2).
//
// Each reference is binned once, by the centre of its box, into a Grid0 cell
// with a 30-bit key; a stable radix sort orders the references by key (the
// GPU version uses CUDPP radix sort). Runs of equal 21-bit prefixes are the
// non-empty top cells (TopGrid0 holds their rank, bottomGridIDs), and only
// those get an 8^3 bottom grid. A bottom grid is stored compactly: a 512-bit
// occupancy mask plus the first sorted position of each non-empty cell, so
// memory follows the occupied cells, not 2 KB per top cell (a dense 8^3 block
// per top cell reaches gigabytes on triangle soups). The bottom-grid key is a
// Morton code, so a Grid1 (512^3) or Grid2 (256^3) cell is a run of 8 or 64
// consecutive keys and its count is one difference of first positions: these
// two levels of detail are implicit. Grid3 (128^3) is TopGrid0 itself, and
// Grid4..Grid7 (64^3 .. 8^3) are dense count arrays (1.2 MB in all), each
// cell the sum of its 8 children (Fig. 4.2). How the levels are stored is left
// open by the dissertation (§8).
#include "accel/bvh/builders/grid_bvh_sparse_grid.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf::gridbvh {
namespace {

constexpr uint32_t kSortBlock = 16 * 1024;  // elements per radix-sort histogram block
constexpr int kDigitBits = 10;
constexpr uint32_t kDigits = 1u << kDigitBits;

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Stable LSD radix sort of (key, value) pairs by 30-bit keys, three passes of
// 10 bits. Blocks have a fixed size, so the result is independent of threads.
void radix_sort_30(std::vector<uint32_t>& keys, std::vector<uint32_t>& values) {
    const uint32_t n = uint32_t(keys.size());
    if (n < 2) return;
    const uint32_t blocks = (n + kSortBlock - 1) / kSortBlock;
    std::vector<uint32_t> key_tmp, value_tmp, hist;
    budgeted_resize(key_tmp, n, "GridBvh: sort keys");
    budgeted_resize(value_tmp, n, "GridBvh: sort values");
    budgeted_resize(hist, size_t{blocks} * kDigits, "GridBvh: sort histograms");
    for (int pass = 0; pass < 3; ++pass) {
        const int shift = pass * kDigitBits;
        parallel::for_each_index(0u, blocks, [&](uint32_t b) {
            uint32_t* h = &hist[size_t{b} * kDigits];
            std::fill(h, h + kDigits, 0u);
            const uint32_t end = std::min(n, (b + 1) * kSortBlock);
            for (uint32_t i = b * kSortBlock; i < end; ++i) ++h[(keys[i] >> shift) & (kDigits - 1)];
        });
        // Exclusive offsets, digit-major then block: stable across blocks.
        uint32_t running = 0;
        for (uint32_t d = 0; d < kDigits; ++d) {
            for (uint32_t b = 0; b < blocks; ++b) {
                const uint32_t c = hist[size_t{b} * kDigits + d];
                hist[size_t{b} * kDigits + d] = running;
                running += c;
            }
        }
        parallel::for_each_index(0u, blocks, [&](uint32_t b) {
            uint32_t* h = &hist[size_t{b} * kDigits];
            const uint32_t end = std::min(n, (b + 1) * kSortBlock);
            for (uint32_t i = b * kSortBlock; i < end; ++i) {
                const uint32_t slot = h[(keys[i] >> shift) & (kDigits - 1)]++;
                key_tmp[slot] = keys[i];
                value_tmp[slot] = values[i];
            }
        });
        keys.swap(key_tmp);
        values.swap(value_tmp);
    }
}

}  // namespace

GridFrame::GridFrame(const Box3f& scene) : origin(scene.lo), extent(scene.extent()) {
    for (int axis = 0; axis < 3; ++axis) {
        const float s = float(kFineRes) / extent[axis];
        to_cell[axis] = (extent[axis] > 0.0f && std::isfinite(s)) ? s : 0.0f;
    }
}

void SparseGrid::build(std::span<const GridRef> refs, const GridFrame& frame, BuildTimes* times) {
    const uint32_t n = checked_index_count("GridBvh references", refs.size());
    auto start = std::chrono::steady_clock::now();

    // Steps 1-3: cell keys of the reference box centres, sorted with the reference ids.
    std::vector<uint32_t> keys;
    budgeted_resize(keys, n, "GridBvh: cell keys");
    budgeted_resize(sorted_, n, "GridBvh: sorted references");
    parallel::for_range(0u, n, 16u * 1024u, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i < hi; ++i) {
            keys[i] = fine_key(frame, refs[i].centroid());
            sorted_[i] = i;
        }
    });
    radix_sort_30(keys, sorted_);
    if (times) times->sort_ms = ms_since(start);
    start = std::chrono::steady_clock::now();

    // Steps 4-5: compaction of the sorted keys on 21 bits (top cells) and on
    // 30 bits (non-empty Grid0 cells, with their bottom-grid occupancy bits).
    top_key_.clear();
    top_begin_.clear();
    top_cells_.clear();
    top_mask_.clear();
    fine_begin_.clear();
    for (uint32_t i = 0; i < n; ++i) {
        if (i > 0 && keys[i] == keys[i - 1]) continue;
        if (i == 0 || (keys[i] >> 9) != (keys[i - 1] >> 9)) {
            budgeted_push_back(top_key_, keys[i] >> 9, "GridBvh: top cells");
            budgeted_push_back(top_begin_, i, "GridBvh: top cells");
            budgeted_push_back(top_cells_, uint32_t(fine_begin_.size()), "GridBvh: top cells");
            for (int w = 0; w < kSubCells / 64; ++w) budgeted_push_back(top_mask_, uint64_t{0}, "GridBvh: bottom grids");
        }
        const uint32_t sub = keys[i] & (kSubCells - 1);
        top_mask_[top_mask_.size() - kSubCells / 64 + sub / 64] |= uint64_t{1} << (sub % 64);
        budgeted_push_back(fine_begin_, i, "GridBvh: bottom grid cells");
    }
    budgeted_push_back(top_begin_, n, "GridBvh: top cells");
    budgeted_push_back(top_cells_, uint32_t(fine_begin_.size()), "GridBvh: top cells");
    budgeted_push_back(fine_begin_, n, "GridBvh: bottom grid cells");
    const uint32_t occupied = uint32_t(top_key_.size());
    const uint32_t top_cells = uint32_t(kTopRes) * kTopRes * kTopRes;
    budgeted_resize(top_index_, top_cells, "GridBvh: TopGrid0");
    parallel::for_range(0u, top_cells, 64u * 1024u, [&](uint32_t lo, uint32_t hi) {
        std::fill(top_index_.begin() + lo, top_index_.begin() + hi, kEmpty);
    });
    parallel::for_range(0u, occupied, 16u * 1024u, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t m = lo; m < hi; ++m) top_index_[top_key_[m]] = m;
    });
    if (times) times->grid0_ms = ms_since(start);
    start = std::chrono::steady_clock::now();

    // Step 6: Grid4..Grid7, each cell the sum of its 8 children.
    for (int k = 0; k < 4; ++k) {
        const uint32_t res = uint32_t(kFineRes) >> (4 + k);
        dense_[k].assign(0, 0);
        budgeted_resize(dense_[k], size_t{res} * res * res, "GridBvh: coarse grid levels");
    }
    for (uint32_t m = 0; m < occupied; ++m) {
        const uint32_t key = top_key_[m];
        const uint32_t x = key % kTopRes, y = (key / kTopRes) % kTopRes, z = key / (kTopRes * kTopRes);
        const uint32_t res = kTopRes / 2;
        dense_[0][(x >> 1) + res * ((y >> 1) + res * (z >> 1))] += top_begin_[m + 1] - top_begin_[m];
    }
    for (int k = 1; k < 4; ++k) {
        const uint32_t res = uint32_t(kFineRes) >> (4 + k), child_res = 2 * res;
        const std::vector<uint32_t>& child = dense_[k - 1];
        std::vector<uint32_t>& parent = dense_[k];
        parallel::for_range(0u, res * res * res, 4096u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t c = lo; c < hi; ++c) {
                const uint32_t x = c % res, y = (c / res) % res, z = c / (res * res);
                uint32_t sum = 0;
                for (uint32_t d = 0; d < 8; ++d) {
                    const uint32_t cx = 2 * x + (d & 1), cy = 2 * y + ((d >> 1) & 1), cz = 2 * z + (d >> 2);
                    sum += child[cx + child_res * (cy + child_res * cz)];
                }
                parent[c] = sum;
            }
        });
    }
    if (times) times->coarse_ms = ms_since(start);
}

void SparseGrid::collect(int level, const CellBox& box, std::vector<uint32_t>& out) const {
    for (int z = box.lo[2]; z <= box.hi[2]; ++z) {
        for (int y = box.lo[1]; y <= box.hi[1]; ++y) {
            for (int x = box.lo[0]; x <= box.hi[0]; ++x) {
                if (level >= 4) {
                    if (count(level, x, y, z) == 0) continue;
                    const CellBox child{{uint16_t(2 * x), uint16_t(2 * y), uint16_t(2 * z)},
                                        {uint16_t(2 * x + 1), uint16_t(2 * y + 1), uint16_t(2 * z + 1)}};
                    collect(level - 1, child, out);
                    continue;
                }
                // At Grid3 and finer a cell's references are one contiguous run.
                const int shift = 3 - level;
                const SparseGridView g = view();
                const uint32_t m = top_rank(g, x >> shift, y >> shift, z >> shift);
                if (m == kEmpty) continue;
                uint32_t first = top_begin_[m], end = top_begin_[m + 1];
                if (level < 3) {
                    const uint32_t mask = (kSubRes >> level) - 1;
                    const uint32_t key = morton9((uint32_t(x) & mask) << level, (uint32_t(y) & mask) << level,
                                                 (uint32_t(z) & mask) << level);
                    sub_range(g, m, key, key + (1u << (3 * level)), first, end);
                }
                for (uint32_t i = first; i < end; ++i) out.push_back(i);
            }
        }
    }
}

size_t SparseGrid::memory_bytes() const {
    size_t bytes = (sorted_.capacity() + top_index_.capacity() + top_key_.capacity() + top_begin_.capacity() +
                    top_cells_.capacity() + fine_begin_.capacity()) *
                       sizeof(uint32_t) +
                   top_mask_.capacity() * sizeof(uint64_t);
    for (const auto& level : dense_) bytes += level.capacity() * sizeof(uint32_t);
    return bytes;
}

}  // namespace rf::gridbvh
