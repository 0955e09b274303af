// Uniform grid on the device by sorting (cell, triangle) pairs: Kalojanov
// and Slusallek, "A Parallel Algorithm for Construction of Uniform Grids"
// (HPG 2009), §3, building rf::build_uniform_grid's grid:
//  0. bounds:  a thread per triangle, block-wise unions of the triangle boxes,
//     then one block over the block results; the host chooses the layout
//     from them (choose_grid_layout) and the cell margin (cell_inflation).
//  1. count:   a thread per triangle counts the cells it overlaps
//     (uniform_grid_steps::count_overlapped_cells: the CPU's cell walk and
//     SAT test, so the cells are exactly the CPU's).
//  2. scan:    cub::DeviceScan::ExclusiveSum of the counts, in 64 bits, gives
//     each triangle its write offset and the total, which must fit 32 bits.
//  3. write:   the thread writes its (cell, triangle) pairs at its offset;
//     the pairs are in triangle order.
//  4. sort:    one cub::DeviceRadixSort::SortPairs by cell over just the
//     bits of the largest cell index. The LSD sort is stable, so each cell's
//     triangles stay ascending: the CPU's cell lists.
//  5. ranges:  a thread per cell finds its first pair by binary search
//     (uniform_grid_steps::cell_start_of), empty cells included, giving
//     the CPU's cell_start.
//  6. proximity clouds (when asked): the occupancy from cell_start, then
//     three 1D passes of the Chebyshev distance transform (x, y, z), a thread
//     per cell (uniform_grid_steps::chessboard_pass_at), in bytes saturated at
//     255: exactly the CPU's proximity bytes.
//  7. cell_start, the sorted triangles and the proximity bytes go back to the
//     host, into arrays under the host memory budget.
// Stages are timed with CUDA events around their kernels; every device
// buffer is counted by the MemoryMeter and lives in the scope of the stages
// that need it.
#include <cuda_runtime.h>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <limits>
#include <string>
#include <vector>

#include "accel/grid/uniform_grid.h"
#include "accel/grid/uniform_grid_steps.h"
#include "backend/backends.h"
#include "backend/cuda/build_context.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/launch.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::cuda {
namespace {

namespace steps = uniform_grid_steps;

constexpr uint32_t kMaxBoundsBlocks = 1024;  // block results the second reduction pass unions

// The grid shape a distance-transform thread needs.
struct GridDims {
    int dims[3];
};

// A box union over the block's threads, valid in thread 0: a tree in shared
// memory (float min/max, so the order of the unions does not matter).
__device__ Box3f block_union(Box3f box) {
    __shared__ float lo[3][kBlockSize], hi[3][kBlockSize];  // plain floats: no constructors in shared memory
    for (int a = 0; a < 3; ++a) lo[a][threadIdx.x] = box.lo[a], hi[a][threadIdx.x] = box.hi[a];
    __syncthreads();
    for (int half = kBlockSize / 2; half > 0; half >>= 1) {
        if (threadIdx.x < half) {
            for (int a = 0; a < 3; ++a) {
                lo[a][threadIdx.x] = fminf(lo[a][threadIdx.x], lo[a][threadIdx.x + half]);
                hi[a][threadIdx.x] = fmaxf(hi[a][threadIdx.x], hi[a][threadIdx.x + half]);
            }
        }
        __syncthreads();
    }
    Box3f result;
    for (int a = 0; a < 3; ++a) result.lo[a] = lo[a][0], result.hi[a] = hi[a][0];
    return result;
}

// Stage 0a: triangle boxes, each block's union.
__global__ void triangle_bounds_kernel(const Triangle* triangles, uint32_t n, Box3f* block_bounds) {
    Box3f acc;
    for (uint32_t i = blockIdx.x * kBlockSize + threadIdx.x; i < n; i += gridDim.x * kBlockSize) {
        acc.extend(triangles[i].bounds());
    }
    acc = block_union(acc);
    if (threadIdx.x == 0) block_bounds[blockIdx.x] = acc;
}

// Stage 0b: one block unions the block results.
__global__ void union_kernel(const Box3f* block_bounds, uint32_t count, Box3f* bounds) {
    Box3f acc;
    for (uint32_t i = threadIdx.x; i < count; i += kBlockSize) acc.extend(block_bounds[i]);
    acc = block_union(acc);
    if (threadIdx.x == 0) *bounds = acc;
}

// Stage 1: a thread per triangle.
__global__ void count_pairs_kernel(steps::CellGridView grid, const Triangle* triangles, uint32_t n,
                                   uint64_t* counts) {
    const uint32_t t = blockIdx.x * kBlockSize + threadIdx.x;
    if (t >= n) return;
    counts[t] = steps::count_overlapped_cells(grid, triangles[t]);
}

// Stage 3: a thread per triangle, from its scanned offset.
__global__ void write_pairs_kernel(steps::CellGridView grid, const Triangle* triangles, uint32_t n,
                                   const uint64_t* offsets, uint32_t* pair_cells, uint32_t* pair_triangles) {
    const uint32_t t = blockIdx.x * kBlockSize + threadIdx.x;
    if (t >= n) return;
    steps::write_cell_pairs(grid, triangles[t], t, static_cast<uint32_t>(offsets[t]), pair_cells, pair_triangles);
}

// Stage 5: a thread per cell, and one for the end of the grid.
__global__ void cell_starts_kernel(const uint32_t* sorted_cells, uint32_t pairs, uint64_t cell_count,
                                   uint32_t* cell_start) {
    const uint64_t c = uint64_t{blockIdx.x} * kBlockSize + threadIdx.x;
    if (c > cell_count) return;
    cell_start[c] = steps::cell_start_of(sorted_cells, pairs, c);
}

// Stage 6a: a thread per cell, 0 where occupied, the cap elsewhere.
__global__ void occupancy_kernel(const uint32_t* cell_start, uint64_t cell_count, uint8_t* distance) {
    const uint64_t c = uint64_t{blockIdx.x} * kBlockSize + threadIdx.x;
    if (c >= cell_count) return;
    distance[c] = steps::occupancy_distance(cell_start, c);
}

// Stage 6b: one 1D pass along `axis`, a thread per cell.
__global__ void chessboard_pass_kernel(const uint8_t* in, uint8_t* out, GridDims grid, int axis, uint64_t cell_count) {
    const uint64_t c = uint64_t{blockIdx.x} * kBlockSize + threadIdx.x;
    if (c >= cell_count) return;
    out[c] = steps::chessboard_pass_at(in, grid.dims, axis, c);
}

// Stage 0, timed as bounds_ms (the two kernels alone: the allocations and
// the download are host work): the triangles' bounds.
Box3f device_bounds(const DeviceBuffer<Triangle>& triangles, uint32_t n, BuildContext& build) {
    const uint32_t blocks = strided_blocks_for(n, kMaxBoundsBlocks);
    DeviceBuffer<Box3f> block_bounds(build.meter, "uniform grid: block bounds", blocks),
        bounds(build.meter, "uniform grid: bounds", 1);
    build.timer.start();
    launch_shaped(triangle_bounds_kernel, {blocks}, triangles.data(), n, block_bounds.data());
    launch_shaped(union_kernel, {1}, block_bounds.data(), blocks, bounds.data());
    build.stages.bounds_ms = build.timer.stop_ms();
    return download_value(bounds.data());
}

// (cell, triangle) pairs.
struct CellPairs {
    DeviceBuffer<uint32_t> cells, triangles;
};

// The pairs in halves[0] and the sort's other half.
struct PairBuffers {
    CellPairs halves[2];
    uint32_t count = 0;
};

// Stages 1-2, timed as cell_pairs_ms: each triangle's pair count and, by a
// 64-bit exclusive scan, its write offset into `offsets`; returns the
// total. The counts and the scan's scratch are freed on return.
uint64_t count_cell_pairs(const steps::CellGridView& view, const DeviceBuffer<Triangle>& triangles, uint32_t n,
                          DeviceBuffer<uint64_t>& offsets, BuildContext& build) {
    DeviceBuffer<uint64_t> counts(build.meter, "uniform grid: pair counts", n);
    DeviceBuffer<uint8_t> scratch(build.meter, "uniform grid: scan temporary storage");
    const auto scan = [&](void* temp, size_t& bytes) {
        return cub::DeviceScan::ExclusiveSum(temp, bytes, counts.data(), offsets.data(), n);
    };
    cub_reserve(scratch, scan);  // allocated outside the timed kernels
    build.timer.start();
    launch(count_pairs_kernel, n, view, triangles.data(), n, counts.data());
    cub_run(scratch, scan);
    build.stages.cell_pairs_ms = build.timer.stop_ms();
    const uint64_t last_offset = download_value(offsets.data() + (n - 1));
    return last_offset + download_value(counts.data() + (n - 1));
}

// Stages 1-3: the (cell, triangle) pairs in triangle order, in halves[0];
// their number must fit 32 bits. The cell planes and the offsets are freed
// on return.
PairBuffers write_cell_pairs(const DeviceBuffer<Triangle>& triangles, uint32_t n, UniformGrid& grid,
                             BuildContext& build) {
    const steps::CellPlanes planes(grid.layout);
    DeviceBuffer<double> device_planes(build.meter, "uniform grid: cell planes", planes.values.size());
    device_planes.upload(planes.values);
    const steps::CellGridView view = planes.view(grid.layout, grid.inflation, device_planes.data());
    DeviceBuffer<uint64_t> offsets(build.meter, "uniform grid: pair offsets", n);
    const uint64_t references = count_cell_pairs(view, triangles, n, offsets, build);
    if (references > std::numeric_limits<uint32_t>::max()) {
        throw Error("uniform grid: " + std::to_string(references) + " cell references exceed 32-bit offsets");
    }
    PairBuffers pairs;
    pairs.count = static_cast<uint32_t>(references);
    build.stages.references = pairs.count;
    budgeted_resize(grid.cell_prims, pairs.count, "uniform grid: cell references");
    const char* const cell_names[2] = {"uniform grid: pair cells", "uniform grid: sorted pair cells"};
    const char* const triangle_names[2] = {"uniform grid: pair triangles", "uniform grid: sorted pair triangles"};
    for (int b = 0; b < 2; ++b) {
        pairs.halves[b] = CellPairs{DeviceBuffer<uint32_t>(build.meter, cell_names[b], pairs.count),
                                    DeviceBuffer<uint32_t>(build.meter, triangle_names[b], pairs.count)};
    }
    if (pairs.count > 0) {
        build.timer.start();
        launch(write_pairs_kernel, n, view, triangles.data(), n, offsets.data(), pairs.halves[0].cells.data(),
               pairs.halves[0].triangles.data());
        build.stages.cell_pairs_ms += build.timer.stop_ms();
    }
    return pairs;
}

// Stage 4, timed as sort_ms: one stable radix sort of the pairs by cell,
// over just the bits of the largest cell index; returns the sorted half
// (the other is freed on return).
CellPairs sort_pairs(PairBuffers pairs, uint64_t cells, BuildContext& build) {
    int sorted = 0;
    if (pairs.count > 0) {
        cub::DoubleBuffer<uint32_t> keys(pairs.halves[0].cells.data(), pairs.halves[1].cells.data());
        cub::DoubleBuffer<uint32_t> values(pairs.halves[0].triangles.data(), pairs.halves[1].triangles.data());
        const int key_bits = steps::cell_key_bits(cells);
        const auto sort = [&](void* temp, size_t& bytes) {
            return cub::DeviceRadixSort::SortPairs(temp, bytes, keys, values, pairs.count, 0, key_bits);
        };
        DeviceBuffer<uint8_t> scratch(build.meter, "uniform grid: radix sort temporary storage");
        cub_reserve(scratch, sort);  // allocated outside the timed sort
        build.timer.start();
        cub_run(scratch, sort);
        build.stages.sort_ms = build.timer.stop_ms();
        sorted = keys.Current() == pairs.halves[0].cells.data() ? 0 : 1;
    }
    return std::move(pairs.halves[sorted]);
}

// Stage 5, timed as cell_ranges_ms: each cell's first pair by binary
// search, empty cells included (the CPU's cell_start); the sorted cells
// are spent.
DeviceBuffer<uint32_t> cell_ranges(DeviceBuffer<uint32_t> sorted_cells, uint32_t pairs, uint64_t cells,
                                   BuildContext& build) {
    DeviceBuffer<uint32_t> cell_start(build.meter, "uniform grid: cell offsets", cells + 1);
    build.timer.start();
    if (pairs > 0) {
        launch(cell_starts_kernel, cells + 1, sorted_cells.data(), pairs, cells, cell_start.data());
    } else {
        RF_CUDA_CHECK(cudaMemset(cell_start.data(), 0, (cells + 1) * sizeof(uint32_t)));
    }
    build.stages.cell_ranges_ms = build.timer.stop_ms();
    return cell_start;
}

// Stage 6, timed as proximity_ms: the occupancy from cell_start, then the
// x, y and z passes of the distance transform; the pass buffer that does
// not hold the result is freed on return.
DeviceBuffer<uint8_t> proximity_distances(const DeviceBuffer<uint32_t>& cell_start, const GridLayout& layout,
                                          BuildContext& build) {
    const uint64_t cells = layout.cell_count();
    DeviceBuffer<uint8_t> distance[2] = {
        DeviceBuffer<uint8_t>(build.meter, "uniform grid: distance map", cells),
        DeviceBuffer<uint8_t>(build.meter, "uniform grid: distance map (pass)", cells)};
    const GridDims dims{{layout.dims[0], layout.dims[1], layout.dims[2]}};
    int result = 0;
    build.timer.start();
    launch(occupancy_kernel, cells, cell_start.data(), cells, distance[0].data());
    for (int axis = 0; axis < 3; ++axis) {
        launch(chessboard_pass_kernel, cells, distance[result].data(), distance[1 - result].data(), dims, axis, cells);
        result = 1 - result;
    }
    build.stages.proximity_ms = build.timer.stop_ms();
    return std::move(distance[result]);
}

}  // namespace

UniformGrid build_uniform_grid_on_device(std::span<const Triangle> triangles, int resolution, bool proximity_clouds,
                                         DeviceBuildStages* stages, int device) {
    DeviceBuildStages local;
    DeviceBuildStages& s = stages ? *stages : local;
    s = {};
    UniformGrid grid;
    if (triangles.size() > std::numeric_limits<uint32_t>::max() - 1) {
        throw Error("uniform grid: " + std::to_string(triangles.size()) + " triangles exceed 32-bit indices");
    }
    const uint32_t n = static_cast<uint32_t>(triangles.size());
    if (n == 0) {  // no cells: nothing for the device to do
        grid.layout = choose_grid_layout(Box3f{}, 0, resolution);
        return grid;
    }
    require_device(device);
    RF_CUDA_CHECK(cudaSetDevice(device));
    BuildContext build(s);
    PairBuffers pairs;
    {
        DeviceBuffer<Triangle> device_triangles(build.meter, "uniform grid: triangles", n);
        build.timer.start();
        device_triangles.upload(triangles);
        s.upload_ms = build.timer.stop_ms();
        // 0. Bounds on the device, the layout and the margin on the host.
        grid.layout = choose_grid_layout(device_bounds(device_triangles, n, build), n, resolution);
        const uint64_t cells = grid.layout.cell_count();
        if (cells == 0) return grid;  // non-empty input always has cells; kept for symmetry with the CPU
        grid.inflation = steps::cell_inflation(grid.layout);
        // The host arrays first: over the budget, fail before any device work.
        budgeted_resize(grid.cell_start, cells + 1, "uniform grid: cell offsets");
        if (proximity_clouds) budgeted_resize(grid.proximity, cells, "uniform grid: proximity clouds");
        // 1-3. Count, scan, write; the triangles are spent then.
        pairs = write_cell_pairs(device_triangles, n, grid, build);
    }
    // 4-6. Sort, cell ranges, proximity clouds.
    const uint64_t cells = grid.layout.cell_count();
    const uint32_t pair_count = pairs.count;
    CellPairs sorted = sort_pairs(std::move(pairs), cells, build);
    const DeviceBuffer<uint32_t> cell_start = cell_ranges(std::move(sorted.cells), pair_count, cells, build);
    DeviceBuffer<uint8_t> distance;
    if (proximity_clouds) distance = proximity_distances(cell_start, grid.layout, build);

    // 7. Back to the host.
    build.timer.start();
    cell_start.download(grid.cell_start);
    sorted.triangles.download(grid.cell_prims);
    if (proximity_clouds) distance.download(grid.proximity);
    s.download_ms = build.timer.stop_ms();
    s.peak_device_bytes = build.meter.peak();
    return grid;
}

}  // namespace rf::cuda
