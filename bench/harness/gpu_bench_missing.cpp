// Stand-in for gpu_bench.cpp when rayforge is built without the CUDA backend:
// asking for a device throws the "not built" error.
#include "gpu_bench.h"

#include "rayforge/core/error.h"

namespace rf::bench {

bool gpu_bench_available() { return false; }
void require_gpu_device(int) { throw Error(kCudaNotBuilt); }
std::string gpu_device_name(int) { return ""; }

struct GpuTracer::Impl {};
GpuTracer::GpuTracer(const SceneGeometry&, GpuKernel, const BuildOptions&, int) { throw Error(kCudaNotBuilt); }
GpuTracer::~GpuTracer() = default;
void GpuTracer::upload(std::span<const Ray>) {}
double GpuTracer::trace(bool) { return 0.0; }
void GpuTracer::download_hits(std::span<Hit>) const {}
void GpuTracer::download_occluded(std::span<uint8_t>) const {}
void GpuTracer::count_traversal(std::span<const Ray>, bool, TraversalTotals&) const {}
AccelStats GpuTracer::stats() const { return {}; }
size_t GpuTracer::device_bytes() const { return 0; }

GpuBuildStages GpuTracer::build_stages() const { return {}; }

GpuBuildStages gpu_build(std::span<const Triangle>, const BuildOptions&, int, Bvh*) { throw Error(kCudaNotBuilt); }
GpuBuildStages gpu_build_grid(std::span<const Triangle>, int, bool, int) { throw Error(kCudaNotBuilt); }
GpuBuildStages gpu_convert_layout(const Bvh&, std::span<const Triangle>, GpuKernel, int) { throw Error(kCudaNotBuilt); }

struct GpuRenderer::Impl {};
GpuRenderer::GpuRenderer(const Scene&, const SceneGeometry&, const Camera&, const RenderOptions&, GpuKernel,
                         const BuildOptions&, int) {
    throw Error(kCudaNotBuilt);
}
GpuRenderer::~GpuRenderer() = default;
GpuPass GpuRenderer::render_pass() { return {}; }
AccelStats GpuRenderer::accel_stats() const { return {}; }

}  // namespace rf::bench
