// A structure on one CUDA device with the traversal kernel that reads it
// (BuildOptions::gpu_kernel): built on the device when
// BuildOptions::build_on_device is set and the builder has a device version
// (device_builders.h; the layout conversion then runs there too), else on
// the CPU; then converted to the kernel's layout (node pairs, CWBVH, kd
// nodes, grid cells) and uploaded with the triangles. The CUDA backend's
// rf::Accel (cuda_accel.cpp) and renderer (renderer.cu) are built on it.
//
// Animated scenes (backend/cuda/device_dynamic_accel.cpp) use two more
// forms: a BVH made refittable keeps its canonical tree on the device and
// refit() recomputes its boxes there (bvh_refit.cu); and a tracer over a
// DeviceTwoLevel traces a two-level structure that its owner updates.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "backend/backends.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/two_level_trace.h"
#include "rayforge/accel/accel.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Kernel time of one launch, from CUDA events around the launch alone.
struct KernelTiming {
    double kernel_ms = 0.0;
    uint64_t rays = 0;
};

// Whether a BVH tracer keeps what refit() needs.
enum class Refittable : uint8_t { No, Yes };

class DeviceTracer {
public:
    // options.gpu_kernel over `geometry` on device options.device.index.
    DeviceTracer(const SceneGeometry& geometry, const BuildOptions& options, Refittable refittable = Refittable::No);
    // Traces `two_level` (kernel bvh2 at both levels); stats as given.
    DeviceTracer(std::unique_ptr<DeviceTwoLevel> two_level, AccelStats stats);
    ~DeviceTracer();
    DeviceTracer(const DeviceTracer&) = delete;
    DeviceTracer& operator=(const DeviceTracer&) = delete;

    // Host rays in, host answers out (uploads, one launch, downloads), on a
    // stream and buffers of the call's own: concurrent calls are safe.
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    // Rays and answers in this device's memory (hits for the closest hit,
    // else occluded), traced on `stream` (a cudaStream_t, nullptr: the
    // default stream); returns when the stream has finished. rf::Error for a
    // pointer that is not memory of this device. Concurrent calls are safe.
    void trace_on_device(const Ray* rays, Hit* hits, uint8_t* occluded, size_t count, void* stream) const;

    // Rays resident on the device, so that a launch measures traversal alone
    // (the bench: one caller at a time).
    void upload_rays(std::span<const Ray> rays);
    KernelTiming trace_uploaded(bool any_hit);
    void download_hits(std::span<Hit> hits) const;           // after trace_uploaded(false)
    void download_occluded(std::span<uint8_t> flags) const;  // after trace_uploaded(true)

    // A refittable BVH's boxes recomputed on the device for `triangles` (the
    // geometry's, same count and order as at construction, new positions),
    // the topology kept: the bvh2 kernel traces the refitted nodes in place;
    // node pairs and CWBVH are converted again from them (on the device when
    // the build was). Returns the refit kernel's milliseconds; rf::Error when
    // the tracer was not made refittable.
    double refit(std::span<const Triangle> triangles);
    // The two-level structure this tracer traces (null for the others).
    [[nodiscard]] DeviceTwoLevel* two_level();

    // Instrumented traversal (node or cell visits, triangle tests, restarts), like Accel::count_traversal.
    void count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const;

    [[nodiscard]] GpuKernel kernel() const;
    [[nodiscard]] int device() const;
    // name "cuda/<kernel>/<builder>", build_ms (build + layout + upload, wall time), layout_ms, nodes,
    // bytes and device_bytes.
    [[nodiscard]] AccelStats stats() const;
    void set_stats(const AccelStats& stats);
    // The build's stages (on_device false: built on the host, no stages).
    [[nodiscard]] const DeviceBuildStages& build_stages() const;

    struct Impl;
    [[nodiscard]] const Impl& impl() const { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

// The registers, local memory and occupancy of the trace launches of
// `kernel` (closest and any hit) on `device`, as launch_trace launches them
// (device_tracer.cu; empty for a kernel whose launches live elsewhere).
std::vector<GpuKernelResources> trace_kernel_resources(GpuKernel kernel, int device);

}  // namespace rf::cuda
