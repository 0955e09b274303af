// The bench's view of the CUDA backend (rf::cuda, include/rayforge/backend/cuda.h)
// behind a CUDA-free interface, so the runner and the CLI compile the same
// way with or without the backend. gpu_bench.cpp forwards to rf::cuda when
// the backend is built; gpu_bench_missing.cpp otherwise, where every
// constructor throws the "not built" error. Which kernel traces which build:
// gpu_candidates.h.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "device_build_report.h"
#include "gpu_candidates.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/backend/device.h"
#include "rayforge/math/ray.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::bench {

// The message of every GPU request in a build without the backend.
inline constexpr const char* kCudaNotBuilt =
    "this rayforge was built without the CUDA backend (nvcc was not found at configure time)";

bool gpu_bench_available();  // == rf::cuda_backend_built()
// Throws rf::Error naming why `device` cannot be used (not built, no driver, no such device).
void require_gpu_device(int device);
// The device's name from the driver, "" when it cannot be used.
std::string gpu_device_name(int device);

// A structure resident on one device with its traversal kernel (rf::cuda::DeviceTracer).
class GpuTracer {
public:
    GpuTracer(const SceneGeometry& geometry, GpuKernel kernel, const BuildOptions& build, int device);
    ~GpuTracer();
    GpuTracer(const GpuTracer&) = delete;
    GpuTracer& operator=(const GpuTracer&) = delete;

    // Rays stay on the device; trace() times one launch with CUDA events (ms).
    void upload(std::span<const Ray> rays);
    double trace(bool any_hit);
    void download_hits(std::span<Hit> hits) const;          // after trace(false)
    void download_occluded(std::span<uint8_t> flags) const;  // after trace(true)
    void count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const;

    [[nodiscard]] AccelStats stats() const;  // build_ms: build + layout + upload (wall time)
    [[nodiscard]] size_t device_bytes() const;
    // The stages of the structure's build and layout conversion (on_device false: built on the host).
    [[nodiscard]] GpuBuildStages build_stages() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// options.builder on `device` (rf::cuda::build_bvh_on_device); throws
// rf::Error for a builder without a device version.
GpuBuildStages gpu_build(std::span<const Triangle> triangles, const BuildOptions& options, int device,
                         Bvh* bvh_out = nullptr);
// A uniform grid (with the proximity clouds when asked) on `device`.
GpuBuildStages gpu_build_grid(std::span<const Triangle> triangles, int resolution, bool proximity, int device);
// The conversion of `bvh` to `kernel`'s layout (aila-laine or cwbvh) on `device`: one "layout" stage.
GpuBuildStages gpu_convert_layout(const Bvh& bvh, std::span<const Triangle> triangles, GpuKernel kernel, int device);

// What one pass of the device renderer did.
struct GpuPass {
    double pass_ms = 0.0;
    uint64_t closest_rays = 0, shadow_rays = 0;
};

// Progressive rendering on one device (rf::cuda::Renderer), for the render bench.
class GpuRenderer {
public:
    // Everything passed must outlive the renderer.
    GpuRenderer(const Scene& scene, const SceneGeometry& geometry, const Camera& camera, const RenderOptions& options,
                GpuKernel kernel, const BuildOptions& build, int device);
    ~GpuRenderer();
    GpuRenderer(const GpuRenderer&) = delete;
    GpuRenderer& operator=(const GpuRenderer&) = delete;

    GpuPass render_pass();
    [[nodiscard]] AccelStats accel_stats() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace rf::bench
