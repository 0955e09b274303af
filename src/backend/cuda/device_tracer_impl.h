// DeviceTracer's state (device_tracer.h), shared by the trace kernels
// (device_tracer.cu) and the renderer (renderer.cu): the structure's arrays
// in device memory and, per GPU kernel, the tracer struct over them
// (trace/tracers.h, the CPU's own).
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "backend/cuda/bvh_refit.h"
#include "backend/cuda/device_buffer.h"
#include "trace/tracers.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_tracer.h"

namespace rf::cuda {

// One batch call's device memory and stream: DeviceTracer's batches take
// one from the pool for the call and give it back (BatchScratchLease), so
// concurrent calls never share a buffer, a ray counter or a stream.
struct BatchScratch {
    explicit BatchScratch(int device);
    ~BatchScratch();
    BatchScratch(const BatchScratch&) = delete;
    BatchScratch& operator=(const BatchScratch&) = delete;
    DeviceBuffer<Ray> rays{"batch rays"};
    DeviceBuffer<Hit> hits{"batch hits"};
    DeviceBuffer<uint8_t> flags{"batch occlusion flags"};
    DeviceBuffer<uint32_t> counter{"batch ray counter", 1};  // the persistent kernel's
    cudaStream_t stream = nullptr;                           // non-blocking, of this scratch
};

class BatchScratchPool {
public:
    std::unique_ptr<BatchScratch> take(int device) {
        {
            const std::lock_guard<std::mutex> lock(mutex_);
            if (!free_.empty()) {
                std::unique_ptr<BatchScratch> s = std::move(free_.back());
                free_.pop_back();
                return s;
            }
        }
        return std::make_unique<BatchScratch>(device);
    }
    void give_back(std::unique_ptr<BatchScratch> s) {
        const std::lock_guard<std::mutex> lock(mutex_);
        free_.push_back(std::move(s));
    }

private:
    std::mutex mutex_;
    std::vector<std::unique_ptr<BatchScratch>> free_;
};

class BatchScratchLease {
public:
    BatchScratchLease(BatchScratchPool& pool, int device) : pool_(pool), scratch_(pool.take(device)) {}
    ~BatchScratchLease() { pool_.give_back(std::move(scratch_)); }
    BatchScratchLease(const BatchScratchLease&) = delete;
    BatchScratchLease& operator=(const BatchScratchLease&) = delete;
    BatchScratch& operator*() const { return *scratch_; }
    BatchScratch* operator->() const { return scratch_.get(); }

private:
    BatchScratchPool& pool_;
    std::unique_ptr<BatchScratch> scratch_;
};

// Where one trace reads and writes: device rays, the answers (hits for
// the closest hit, flags for any hit), the persistent kernels' ray counter
// (reset to 0 before the launch), the stream.
struct TraceTarget {
    const Ray* rays = nullptr;
    Hit* hits = nullptr;
    uint8_t* flags = nullptr;
    uint32_t* counter = nullptr;
    cudaStream_t stream = nullptr;
};

// Kernels scheduled as persistent threads taking rays from TraceTarget::counter.
inline bool uses_ray_counter(GpuKernel kernel) {
    return kernel == GpuKernel::AilaLaine || kernel == GpuKernel::AilaLaineFma || kernel == GpuKernel::CwbvhFma;
}

struct DeviceTracer::Impl {
    GpuKernel kernel = GpuKernel::Bvh2;
    int device = 0;
    AccelStats stats;
    DeviceBuildStages build_stages;  // of the structure's build and layout conversion (on_device: where)
    int multiprocessors = 1;
    int persistent_blocks[2] = {0, 0};  // persistent kernels' grid size, closest / any hit (set once, under persistent_once)
    std::once_flag persistent_once;

    DeviceBuffer<Triangle> triangles{"triangles"};
    // The arrays of whichever structure the kernel reads.
    DeviceBuffer<BvhNode> bvh_nodes{"bvh nodes"};
    DeviceBuffer<uint32_t> prim_indices{"primitive indices"};
    DeviceBuffer<AilaLaineNode> aila_laine_nodes{"node pairs"};
    DeviceBuffer<AilaLaineFloat4> aila_laine_triangles{"node-pair leaf triangles"};
    DeviceBuffer<CwbvhNode> cwbvh_nodes{"cwbvh nodes"};
    DeviceBuffer<CwbvhTriangle> cwbvh_triangles{"cwbvh leaf triangles"};
    DeviceBuffer<KdNode> kd_nodes{"kd-tree nodes"};
    DeviceBuffer<uint32_t> cell_start{"grid cell offsets"};
    DeviceBuffer<uint32_t> cell_prims{"grid cell references"};
    DeviceBuffer<uint8_t> proximity{"proximity distances"};

    // A refittable BVH (Refittable::Yes): its canonical tree, slots and
    // triangles on the device, refitted there; the bvh2 kernel reads them
    // (bvh_nodes, prim_indices and triangles stay empty), the other layouts
    // are converted again from host_bvh, the refitted nodes copied back.
    std::unique_ptr<DeviceBvhRefit> refitter;
    Bvh host_bvh;
    bool convert_on_device = false;
    // A two-level structure (the second constructor), traced instead of the above.
    std::unique_ptr<DeviceTwoLevel> two_level;

    Bvh2Tracer bvh2{};
    AilaLaineTracer aila_laine{};
    AilaLaineFmaTracer aila_laine_fma{};  // the same arrays as aila_laine
    CwbvhTracer cwbvh{};
    CwbvhFmaTracer cwbvh_fma{};           // the same arrays as cwbvh
    KdTracer<KdTraversal::ShortStack> kd_short_stack{};
    KdTracer<KdTraversal::Restart> kd_restart{};
    GridTracer grid{};

    // The batches' scratch (intersect, occluded, trace_on_device).
    BatchScratchPool batch_scratch;
    // Rays resident on the device (the bench) and the answers.
    DeviceBuffer<Ray> rays{"rays"};
    DeviceBuffer<Hit> hits{"hits"};
    DeviceBuffer<uint8_t> flags{"occlusion flags"};
    DeviceBuffer<uint32_t> work_counter{"persistent-thread ray counter"};
    DeviceBuffer<unsigned long long> totals{"traversal totals"};

    // Device memory of the structure and its triangles (not the ray buffers).
    [[nodiscard]] size_t structure_bytes() const;

    // Calls f with the tracer struct of this kernel.
    template <class F>
    decltype(auto) with_tracer(F&& f) const {
        if (two_level) return f(two_level->tracer());
        switch (kernel) {
            case GpuKernel::Bvh2: return f(bvh2);
            case GpuKernel::AilaLaine: return f(aila_laine);
            case GpuKernel::AilaLaineFma: return f(aila_laine_fma);
            case GpuKernel::Cwbvh: return f(cwbvh);
            case GpuKernel::CwbvhFma: return f(cwbvh_fma);
            case GpuKernel::KdShortStack: return f(kd_short_stack);
            case GpuKernel::KdRestart: return f(kd_restart);
            case GpuKernel::Grid:
            case GpuKernel::ProximityGrid: return f(grid);
        }
        return f(bvh2);
    }
};

}  // namespace rf::cuda
