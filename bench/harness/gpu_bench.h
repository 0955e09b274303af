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

#include "gpu_candidates.h"
#include "rayforge/accel/accel.h"
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

    [[nodiscard]] AccelStats stats() const;  // build_ms: CPU build + layout + upload
    [[nodiscard]] size_t device_bytes() const;

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

// One device build with its stages (rf::cuda::DeviceBuildStages): device
// stages in pipeline order, then the transfers and the host's part.
struct GpuBuildStages {
    std::vector<std::pair<std::string, double>> device_stages;  // name -> ms
    double device_ms = 0.0;                                     // their sum
    double upload_ms = 0.0, download_ms = 0.0, host_ms = 0.0;
    size_t peak_device_bytes = 0;
    size_t nodes = 0;
    double sah_cost = 0.0;
    std::string detail;  // builder-specific sizes (clusters, levels)
};
// LBVH (Karras 2012) on `device` with `morton_bits` (30 or 63).
GpuBuildStages gpu_build_lbvh(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits,
                              int device);
// HLBVH2 (Garanzha 2014 ch. 5) on `device`; its top level runs on the host
// for now and is listed among the host's work.
GpuBuildStages gpu_build_hlbvh2(std::span<const Triangle> triangles, const BuildOptions& options, int device);

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
