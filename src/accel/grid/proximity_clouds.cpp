// Chebyshev distance transform for proximity clouds: Meijster, Roerdink and
// Hesselink 2000, the L-inf ("chessboard") instance of their separable
// lower-envelope scheme, applied along x, then y, then z.
#include "accel/grid/proximity_clouds.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

// "Infinitely far": larger than any distance, small enough that index + kFar
// stays within int32 (dims are far below 2^29).
constexpr int32_t kFar = int32_t{1} << 29;
// Lines processed together in the y and z passes: they are adjacent in x, so
// gathering them reads whole cache lines.
constexpr size_t kLinesPerBlock = 16;

// out[x] = min_i max(|x - i|, g[i]) in O(n) (Meijster et al., phase 2 with
// f(x, i) = max(|x - i|, g(i)) and the chessboard Sep). s and t hold the
// lower envelope: s[q] is the index whose function is minimal from t[q] on.
void chessboard_pass(const int32_t* g, int32_t* out, int32_t* s, int32_t* t, int32_t n) {
    auto f = [&](int32_t x, int32_t i) { return std::max(x > i ? x - i : i - x, g[i]); };
    // Largest x at which i's function is still no larger than u's (i < u).
    auto sep = [&](int32_t i, int32_t u) {
        const int32_t mid = (i + u) / 2;
        return g[i] <= g[u] ? std::max(i + g[u], mid) : std::min(u - g[i], mid);
    };
    int32_t q = 0;
    s[0] = 0;
    t[0] = 0;
    for (int32_t u = 1; u < n; ++u) {
        while (q >= 0 && f(t[q], s[q]) > f(t[q], u)) --q;
        if (q < 0) {
            q = 0;
            s[0] = u;
        } else {
            const int32_t start = 1 + sep(s[q], u);
            if (start < n) {
                ++q;
                s[q] = u;
                t[q] = start;
            }
        }
    }
    for (int32_t u = n - 1; u >= 0; --u) {
        out[u] = f(u, s[q]);
        if (u == t[q]) --q;
    }
}

int32_t widen(uint32_t d) { return d == kNoOccupiedCell ? kFar : static_cast<int32_t>(d); }
uint32_t narrow(int32_t d) { return d >= kFar ? kNoOccupiedCell : static_cast<uint32_t>(d); }

// x pass: on binary input the transform is the 1D distance to the nearest
// occupied cell of the row, two scans.
void pass_x(std::vector<uint32_t>& dist, std::array<int, 3> dims) {
    const size_t nx = static_cast<size_t>(dims[0]);
    const size_t rows = static_cast<size_t>(dims[1]) * static_cast<size_t>(dims[2]);
    parallel::for_range(size_t(0), rows, std::max<size_t>(1, 16384 / nx), [&](size_t lo, size_t hi) {
        for (size_t row = lo; row < hi; ++row) {
            uint32_t* d = dist.data() + row * nx;
            int32_t run = kFar;
            for (size_t x = 0; x < nx; ++x) {
                run = d[x] == 0 ? 0 : std::min(run + 1, kFar);
                d[x] = narrow(run);
            }
            run = kFar;
            for (size_t x = nx; x-- > 0;) {
                run = d[x] == 0 ? 0 : std::min(run + 1, kFar);
                d[x] = std::min(d[x], narrow(run));
            }
        }
    });
}

// y or z pass over every line along `axis`, lines adjacent in x in blocks.
void pass_yz(std::vector<uint32_t>& dist, std::array<int, 3> dims, int axis) {
    const size_t nx = static_cast<size_t>(dims[0]), ny = static_cast<size_t>(dims[1]);
    const size_t n = static_cast<size_t>(dims[axis]);
    const size_t stride = axis == 1 ? nx : nx * ny;
    const size_t other = axis == 1 ? static_cast<size_t>(dims[2]) : ny;  // the third axis
    const size_t other_stride = axis == 1 ? nx * ny : nx;
    const size_t x_blocks = (nx + kLinesPerBlock - 1) / kLinesPerBlock;
    const size_t blocks = x_blocks * other;
    parallel::for_range(size_t(0), blocks, std::max<size_t>(1, 4096 / (n * kLinesPerBlock)), [&](size_t lo, size_t hi) {
        std::vector<int32_t> g(kLinesPerBlock * n), out(n), s(n), t(n);
        for (size_t block = lo; block < hi; ++block) {
            const size_t x0 = (block % x_blocks) * kLinesPerBlock;
            const size_t width = std::min(kLinesPerBlock, nx - x0);
            const size_t base = x0 + (block / x_blocks) * other_stride;
            for (size_t i = 0; i < n; ++i) {
                const uint32_t* row = dist.data() + base + i * stride;
                for (size_t k = 0; k < width; ++k) g[k * n + i] = widen(row[k]);
            }
            for (size_t k = 0; k < width; ++k) {
                const int32_t* line = g.data() + k * n;
                if (std::all_of(line, line + n, [](int32_t v) { return v >= kFar; })) continue;  // nothing near
                chessboard_pass(line, out.data(), s.data(), t.data(), static_cast<int32_t>(n));
                for (size_t i = 0; i < n; ++i) dist[base + k + i * stride] = narrow(out[i]);
            }
        }
    });
}

}  // namespace

std::vector<uint32_t> chebyshev_distance_transform(std::span<const uint8_t> occupied, std::array<int, 3> dims) {
    for (int d : dims) {
        if (d < 1 || d >= kFar / 2) {
            throw Error("chebyshev_distance_transform: grid dimension " + std::to_string(d) + " out of range");
        }
    }
    const size_t cells = static_cast<size_t>(dims[0]) * static_cast<size_t>(dims[1]) * static_cast<size_t>(dims[2]);
    if (occupied.size() != cells) {
        throw Error("chebyshev_distance_transform: " + std::to_string(occupied.size()) + " occupancy flags for " +
                    std::to_string(cells) + " cells");
    }
    // In place, one pass per axis.
    std::vector<uint32_t> dist;
    budgeted_resize(dist, cells, "proximity clouds: distance map");
    parallel::for_range(size_t(0), cells, size_t(1) << 16, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) dist[i] = occupied[i] ? 0 : kNoOccupiedCell;
    });
    pass_x(dist, dims);
    pass_yz(dist, dims, 1);
    pass_yz(dist, dims, 2);
    return dist;
}

}  // namespace rf
