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
// buffer goes through the MemoryMeter, freed as soon as no later stage needs it.
#include <cuda_runtime.h>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <limits>
#include <string>
#include <vector>

#include "accel/grid/uniform_grid.h"
#include "accel/grid/uniform_grid_steps.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/morton_sort.h"
#include "backend/backends.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf::cuda {
namespace {

namespace steps = uniform_grid_steps;

constexpr int kBlockSize = 256;
constexpr uint32_t kMaxBoundsBlocks = 1024;  // block results the second reduction pass unions

uint32_t blocks_for(uint64_t threads) { return static_cast<uint32_t>((threads + kBlockSize - 1) / kBlockSize); }

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

// The triangles' bounds; `kernel_ms` times the two kernels alone (the
// allocations and the download are host work).
Box3f device_bounds(const DeviceBuffer<Triangle>& triangles, uint32_t n, MemoryMeter& meter, EventTimer& timer,
                    double& kernel_ms) {
    DeviceBuffer<Box3f> block_bounds("uniform grid: block bounds"), bounds("uniform grid: bounds");
    const uint32_t blocks = std::min<uint32_t>(blocks_for(n), kMaxBoundsBlocks);
    meter.allocate(block_bounds, blocks);
    meter.allocate(bounds, 1);
    timer.start();
    triangle_bounds_kernel<<<blocks, kBlockSize>>>(triangles.data(), n, block_bounds.data());
    union_kernel<<<1, kBlockSize>>>(block_bounds.data(), blocks, bounds.data());
    RF_CUDA_CHECK(cudaGetLastError());
    kernel_ms = timer.stop_ms();
    Box3f result;
    bounds.download(std::span<Box3f>(&result, 1));
    meter.release(block_bounds);
    meter.release(bounds);
    return result;
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
    MemoryMeter meter;
    EventTimer timer;

    DeviceBuffer<Triangle> device_triangles("uniform grid: triangles");
    meter.allocate(device_triangles, n);
    timer.start();
    device_triangles.upload(triangles);
    s.upload_ms = timer.stop_ms();

    // 0. Bounds on the device, the layout and the margin on the host.
    const Box3f bounds = device_bounds(device_triangles, n, meter, timer, s.bounds_ms);
    grid.layout = choose_grid_layout(bounds, n, resolution);
    const uint64_t cells = grid.layout.cell_count();
    if (cells == 0) return grid;  // non-empty input always has cells; kept for symmetry with the CPU
    grid.inflation = steps::cell_inflation(grid.layout);
    const steps::CellPlanes planes(grid.layout);
    // The host arrays first: over the budget, fail before any device work.
    budgeted_resize(grid.cell_start, cells + 1, "uniform grid: cell offsets");
    if (proximity_clouds) budgeted_resize(grid.proximity, cells, "uniform grid: proximity clouds");

    DeviceBuffer<double> device_planes("uniform grid: cell planes");
    meter.allocate(device_planes, planes.values.size());
    device_planes.upload(planes.values);
    const steps::CellGridView view = planes.view(grid.layout, grid.inflation, device_planes.data());

    // 1-3. Count, scan, write.
    DeviceBuffer<uint64_t> counts("uniform grid: pair counts"), offsets("uniform grid: pair offsets");
    meter.allocate(counts, n);
    meter.allocate(offsets, n);
    size_t scan_bytes = 0;
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, scan_bytes, counts.data(), offsets.data(), n));
    DeviceBuffer<uint8_t> scan_temp("uniform grid: scan temporary storage");
    meter.allocate(scan_temp, scan_bytes > 0 ? scan_bytes : 1);
    timer.start();
    count_pairs_kernel<<<blocks_for(n), kBlockSize>>>(view, device_triangles.data(), n, counts.data());
    RF_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_temp.data(), scan_bytes, counts.data(), offsets.data(), n));
    s.cell_pairs_ms = timer.stop_ms();
    meter.release(scan_temp);
    uint64_t last[2] = {0, 0};
    RF_CUDA_CHECK(cudaMemcpy(&last[0], offsets.data() + (n - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
    RF_CUDA_CHECK(cudaMemcpy(&last[1], counts.data() + (n - 1), sizeof(uint64_t), cudaMemcpyDeviceToHost));
    meter.release(counts);
    const uint64_t references = last[0] + last[1];
    if (references > std::numeric_limits<uint32_t>::max()) {
        throw Error("uniform grid: " + std::to_string(references) + " cell references exceed 32-bit offsets");
    }
    const uint32_t pairs = static_cast<uint32_t>(references);
    s.references = pairs;
    budgeted_resize(grid.cell_prims, pairs, "uniform grid: cell references");

    DeviceBuffer<uint32_t> pair_cells[2] = {DeviceBuffer<uint32_t>("uniform grid: pair cells"),
                                            DeviceBuffer<uint32_t>("uniform grid: sorted pair cells")};
    DeviceBuffer<uint32_t> pair_triangles[2] = {DeviceBuffer<uint32_t>("uniform grid: pair triangles"),
                                                DeviceBuffer<uint32_t>("uniform grid: sorted pair triangles")};
    for (int b = 0; b < 2; ++b) {
        meter.allocate(pair_cells[b], pairs);
        meter.allocate(pair_triangles[b], pairs);
    }
    if (pairs > 0) {
        timer.start();
        write_pairs_kernel<<<blocks_for(n), kBlockSize>>>(view, device_triangles.data(), n, offsets.data(),
                                                          pair_cells[0].data(), pair_triangles[0].data());
        s.cell_pairs_ms += timer.stop_ms();
    }
    meter.release(offsets);
    meter.release(device_triangles);
    meter.release(device_planes);

    // 4. One stable radix sort of the pairs by cell.
    int sorted = 0;
    if (pairs > 0) {
        cub::DoubleBuffer<uint32_t> keys(pair_cells[0].data(), pair_cells[1].data());
        cub::DoubleBuffer<uint32_t> values(pair_triangles[0].data(), pair_triangles[1].data());
        const int key_bits = steps::cell_key_bits(cells);
        size_t sort_bytes = 0;
        RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, sort_bytes, keys, values, pairs, 0, key_bits));
        DeviceBuffer<uint8_t> sort_temp("uniform grid: radix sort temporary storage");
        meter.allocate(sort_temp, sort_bytes > 0 ? sort_bytes : 1);  // a null buffer would make CUB only query
        timer.start();
        RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(sort_temp.data(), sort_bytes, keys, values, pairs, 0, key_bits));
        s.sort_ms = timer.stop_ms();
        meter.release(sort_temp);
        sorted = keys.Current() == pair_cells[0].data() ? 0 : 1;
    }
    meter.release(pair_cells[1 - sorted]);
    meter.release(pair_triangles[1 - sorted]);

    // 5. Cell ranges.
    DeviceBuffer<uint32_t> cell_start("uniform grid: cell offsets");
    meter.allocate(cell_start, cells + 1);
    timer.start();
    if (pairs > 0) {
        cell_starts_kernel<<<blocks_for(cells + 1), kBlockSize>>>(pair_cells[sorted].data(), pairs, cells,
                                                                  cell_start.data());
    } else {
        RF_CUDA_CHECK(cudaMemset(cell_start.data(), 0, (cells + 1) * sizeof(uint32_t)));
    }
    s.cell_ranges_ms = timer.stop_ms();
    meter.release(pair_cells[sorted]);

    // 6. Proximity clouds: occupancy, then the x, y and z passes.
    DeviceBuffer<uint8_t> distance[2] = {DeviceBuffer<uint8_t>("uniform grid: distance map"),
                                         DeviceBuffer<uint8_t>("uniform grid: distance map (pass)")};
    int result = 0;
    if (proximity_clouds) {
        meter.allocate(distance[0], cells);
        meter.allocate(distance[1], cells);
        const GridDims dims{{grid.layout.dims[0], grid.layout.dims[1], grid.layout.dims[2]}};
        timer.start();
        occupancy_kernel<<<blocks_for(cells), kBlockSize>>>(cell_start.data(), cells, distance[0].data());
        for (int axis = 0; axis < 3; ++axis) {
            chessboard_pass_kernel<<<blocks_for(cells), kBlockSize>>>(distance[result].data(),
                                                                      distance[1 - result].data(), dims, axis, cells);
            result = 1 - result;
        }
        s.proximity_ms = timer.stop_ms();
        meter.release(distance[1 - result]);
    }

    // 7. Back to the host.
    timer.start();
    cell_start.download(grid.cell_start);
    pair_triangles[sorted].download(grid.cell_prims);
    if (proximity_clouds) distance[result].download(grid.proximity);
    s.download_ms = timer.stop_ms();
    s.peak_device_bytes = meter.peak();
    return grid;
}

}  // namespace rf::cuda
