// The front of the Morton-ordered device builders (LBVH, lbvh_build.cu;
// HLBVH2, hlbvh2_build.cu), shared so both sort the same way: triangle boxes
// and the centroid bounds (a block-wise union, then one block over the block
// results), 30- or 63-bit Morton codes of the box centres with the CPU's
// MortonQuantizer, and one stable cub::DeviceRadixSort of (code, triangle),
// bit-identical to morton_tree.cpp's. Also the build's bookkeeping: a meter
// of live device bytes and CUDA-event stage timers. Host-only declarations;
// the kernels live in morton_sort.cu.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "backend/cuda/device_buffer.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/device_builders.h"
#include "rayforge/math/box.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Sum of the live device buffers, and its maximum.
class MemoryMeter {
public:
    template <class T>
    void allocate(DeviceBuffer<T>& buffer, size_t count) {
        release(buffer);
        buffer.allocate(count);
        live_ += buffer.bytes();
        if (live_ > peak_) peak_ = live_;
    }
    template <class T>
    void release(DeviceBuffer<T>& buffer) {
        live_ -= buffer.bytes();
        buffer.release();
    }
    [[nodiscard]] size_t peak() const { return peak_; }

private:
    size_t live_ = 0, peak_ = 0;
};

template <class T>
inline std::vector<T> download_all(const DeviceBuffer<T>& buffer, size_t count) {
    std::vector<T> host(count);
    buffer.download(host);
    return host;
}

// The sorted triangles: per-triangle boxes, the sorted codes and the
// stable order (sorted position -> triangle).
template <class Key>
struct DeviceMortonOrder {
    DeviceBuffer<Box3f> boxes;
    DeviceBuffer<Key> keys;
    DeviceBuffer<uint32_t> order;
};

// Uploads `triangles` (n >= 1), computes their boxes, the centroid bounds and
// the codes (uint32_t: 30 bits, uint64_t: 63 bits), and sorts; sets
// stages.upload_ms, bounds_ms, morton_ms and sort_ms. Buffer names start
// with `label` (out-of-memory errors name them); everything else it
// allocated is freed before it returns, all through `meter`.
template <class Key>
void sort_triangles_by_morton_codes(std::span<const Triangle> triangles, const std::string& label,
                                    DeviceBuildStages& stages, MemoryMeter& meter, EventTimer& timer,
                                    DeviceMortonOrder<Key>& out);

}  // namespace rf::cuda
