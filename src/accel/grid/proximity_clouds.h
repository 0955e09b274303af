// Proximity clouds (Bogolepov et al., §2.1.4, after Karlsson and Ljungstedt 2004):
// for every empty grid cell, the Chebyshev (L-inf, chessboard) distance in
// cells to the nearest non-empty cell, so that traversal can skip the cube of
// cells around it that is known to be empty.
//
// Bogolepov et al.'s reference for the distance map is missing; we use the linear-time
// separable transform of Meijster, Roerdink and Hesselink, "A General
// Algorithm for Computing Distance Transforms in Linear Time" (2000), whose
// per-line lower-envelope pass works for the L-inf metric: because
// max(a, max(b, c)) = max(max(a, b), c), the 3D distance is three 1D passes,
// one per axis, each computing min_j max(|i - j|, g(j)) over a line.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

namespace rf {

// Distance of cells with no occupied cell anywhere (an all-empty grid).
inline constexpr uint32_t kNoOccupiedCell = 0xFFFFFFFFu;

// Chebyshev distance from every cell to the nearest occupied cell (0 for
// occupied cells). `occupied` has dims[0] * dims[1] * dims[2] entries, x
// fastest. Parallel over lines; throws rf::Error when over the memory budget.
std::vector<uint32_t> chebyshev_distance_transform(std::span<const uint8_t> occupied, std::array<int, 3> dims);

}  // namespace rf
