// The CUDA backend's public face. Available when rayforge was built with nvcc
// (target rayforge::rayforge_cuda; rf::cuda_backend_built() says so at run
// time); no CUDA header is needed to use it. Every CUDA failure becomes an
// rf::Error naming the file, the line and CUDA's error string; running out of
// device memory names the buffer and the bytes asked for.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/backend/cuda_build.h"
#include "rayforge/backend/device.h"
#include "rayforge/math/ray.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

struct DeviceInfo {
    int index = 0;
    std::string name;
    size_t total_memory = 0;
    size_t free_memory = 0;
    int compute_major = 0, compute_minor = 0;
    int multiprocessors = 0;
    int clock_mhz = 0;         // SM clock
    int memory_bus_bits = 0;
    size_t l2_bytes = 0;
    int driver_version = 0;    // e.g. 13000 for CUDA 13.0
    int runtime_version = 0;
};

// What the CUDA runtime reports: the devices it can use and, when there are
// none (or one could not be queried), why, in the runtime's own words, e.g.
// "cudaGetDeviceCount failed: cudaErrorNoDevice: no CUDA-capable device is
// detected (driver API 0, runtime 13.0)". Never throws.
struct DeviceListing {
    std::vector<DeviceInfo> devices;
    std::string error;  // "" when every device was listed
};
DeviceListing list_devices();
// Throws rf::Error saying why when device `index` cannot be used.
void require_device(int index);

// Kernel time of one launch, from CUDA events around the launch alone.
struct KernelTiming {
    double kernel_ms = 0.0;
    uint64_t rays = 0;
};

// An acceleration structure on one device with the traversal kernel that
// reads it. The structure is built with `build`'s builder and parameters: on
// the device when build.build_on_device is set and the builder has a device
// version (cuda_build.h; the layout conversion then runs there too), else on
// the CPU; then converted to the kernel's layout (node pairs, CWBVH, kd
// nodes, grid cells) and uploaded with the triangles.
class DeviceTracer {
public:
    DeviceTracer(const SceneGeometry& geometry, GpuKernel kernel, const BuildOptions& build = {}, int device = 0);
    ~DeviceTracer();
    DeviceTracer(const DeviceTracer&) = delete;
    DeviceTracer& operator=(const DeviceTracer&) = delete;

    // Host rays in, host answers out (uploads, one launch, downloads).
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;

    // The bench's path: rays stay on the device between launches, so a
    // launch measures traversal alone.
    void upload_rays(std::span<const Ray> rays);
    KernelTiming trace_uploaded(bool any_hit);
    void download_hits(std::span<Hit> hits) const;        // after trace_uploaded(false)
    void download_occluded(std::span<uint8_t> flags) const;  // after trace_uploaded(true)

    // Instrumented traversal (node or cell visits, triangle tests, restarts), like Accel::count_traversal.
    void count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const;

    [[nodiscard]] GpuKernel kernel() const;
    [[nodiscard]] int device() const;
    // name "cuda/<kernel>/<builder>", build_ms (build + layout + upload, wall time), layout_ms, nodes, bytes on
    // the device.
    [[nodiscard]] AccelStats stats() const;
    // The build's stages (on_device false: built on the host, no stages).
    [[nodiscard]] const DeviceBuildStages& build_stages() const;
    [[nodiscard]] size_t device_bytes() const;

    struct Impl;
    [[nodiscard]] const Impl& impl() const { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

// Kept for existing callers: the canonical BVH traced one thread per ray.
class BvhTracer {
public:
    BvhTracer(const Bvh& bvh, std::span<const Triangle> triangles, int device = 0);
    ~BvhTracer();
    BvhTracer(const BvhTracer&) = delete;
    BvhTracer& operator=(const BvhTracer&) = delete;

    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    [[nodiscard]] size_t device_bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// What the device renderer did in its last pass.
struct PassStats {
    double pass_ms = 0.0;               // wall time of the pass, device work included
    std::vector<uint32_t> paths_per_bounce;  // wavefront queue sizes (path integrator)
    uint64_t closest_rays = 0, shadow_rays = 0;
};

// Progressive rendering on one device: one sample per pixel per pass, the
// film accumulated in device memory. The path integrator runs as a wavefront
// (generation, extension, shading, shadow connection and compaction as
// separate kernels over ray queues); Whitted, AO and normals run one thread
// per pixel. Per-sample code is the CPU renderer's (src/render), so the
// images agree with rf::ProgressiveRenderer's.
class Renderer {
public:
    // Everything passed must outlive the renderer. Throws rf::Error for invalid options or CUDA failures.
    Renderer(const Scene& scene, const SceneGeometry& geometry, const Camera& camera, const RenderOptions& options,
             GpuKernel kernel = kDefaultGpuKernel, const BuildOptions& build = {}, int device = 0);
    ~Renderer();
    Renderer(const Renderer&) = delete;
    Renderer& operator=(const Renderer&) = delete;

    void render_pass();
    [[nodiscard]] int passes() const;
    [[nodiscard]] const RenderOptions& options() const;
    [[nodiscard]] RenderStats stats() const;
    [[nodiscard]] const PassStats& last_pass() const;
    // The mean of the passes so far, downloaded from the device.
    [[nodiscard]] Image image() const;
    [[nodiscard]] Image albedo() const;
    [[nodiscard]] Image normal() const;
    [[nodiscard]] Image depth() const;
    [[nodiscard]] const DeviceTracer& tracer() const;

private:
    struct State;
    std::unique_ptr<State> state_;
};

// Called after each pass; return false to stop (the interactive viewer's frame callback).
using DevicePassCallback = std::function<bool(const Renderer& renderer)>;
// Passes until options.spp are done or options.time_budget_s is spent (or the callback stops it).
void render_progressive(Renderer& renderer, const DevicePassCallback& after_pass = {},
                        const ProgressCallback& progress = {});

}  // namespace rf::cuda
