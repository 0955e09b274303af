// gpu_bench.h on the CUDA backend: thin forwards to rf::cuda (compiled only
// when the backend is built; gpu_bench_missing.cpp stands in otherwise).
#include "gpu_bench.h"

#include "rayforge/backend/cuda.h"
#include "rayforge/backend/cuda_build.h"
#include "rayforge/core/error.h"

namespace rf::bench {

bool gpu_bench_available() { return true; }

void require_gpu_device(int device) { cuda::require_device(device); }

std::string gpu_device_name(int device) {
    for (const cuda::DeviceInfo& info : cuda::list_devices())
        if (info.index == device) return info.name;
    return "";
}

struct GpuTracer::Impl {
    cuda::DeviceTracer tracer;
    Impl(const SceneGeometry& geometry, GpuKernel kernel, const BuildOptions& build, int device)
        : tracer(geometry, kernel, build, device) {}
};

GpuTracer::GpuTracer(const SceneGeometry& geometry, GpuKernel kernel, const BuildOptions& build, int device)
    : impl_(std::make_unique<Impl>(geometry, kernel, build, device)) {}
GpuTracer::~GpuTracer() = default;

void GpuTracer::upload(std::span<const Ray> rays) { impl_->tracer.upload_rays(rays); }
double GpuTracer::trace(bool any_hit) { return impl_->tracer.trace_uploaded(any_hit).kernel_ms; }
void GpuTracer::download_hits(std::span<Hit> hits) const { impl_->tracer.download_hits(hits); }
void GpuTracer::download_occluded(std::span<uint8_t> flags) const { impl_->tracer.download_occluded(flags); }
void GpuTracer::count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const {
    impl_->tracer.count_traversal(rays, any_hit, totals);
}
AccelStats GpuTracer::stats() const { return impl_->tracer.stats(); }
size_t GpuTracer::device_bytes() const { return impl_->tracer.device_bytes(); }

namespace {

GpuBuildStages common_stages(const cuda::DeviceBuildStages& s, const Bvh& bvh) {
    GpuBuildStages out;
    out.device_ms = s.device_total_ms();
    out.upload_ms = s.upload_ms;
    out.download_ms = s.download_ms;
    out.host_ms = s.emit_ms + s.top_ms;
    out.peak_device_bytes = s.peak_device_bytes;
    out.nodes = bvh.nodes.size();
    out.sah_cost = bvh.nodes.empty() ? 0.0 : bvh.sah_cost();
    return out;
}

}  // namespace

GpuBuildStages gpu_build_lbvh(std::span<const Triangle> triangles, const BuildOptions& options, int morton_bits,
                              int device) {
    cuda::DeviceBuildStages s;
    const Bvh bvh = cuda::build_lbvh_on_device(triangles, options, morton_bits, &s, device);
    GpuBuildStages out = common_stages(s, bvh);
    out.device_stages = {{"bounds", s.bounds_ms},
                         {"morton", s.morton_ms},
                         {"sort", s.sort_ms},
                         {"inner nodes", s.inner_nodes_ms},
                         {"boxes", s.boxes_ms}};
    return out;
}

GpuBuildStages gpu_build_hlbvh2(std::span<const Triangle> triangles, const BuildOptions& options, int device) {
    cuda::DeviceBuildStages s;
    const Bvh bvh = cuda::build_hlbvh2_on_device(triangles, options, &s, device);
    GpuBuildStages out = common_stages(s, bvh);
    out.device_stages = {{"bounds", s.bounds_ms},  {"morton", s.morton_ms},  {"sort", s.sort_ms},
                         {"clusters", s.clusters_ms}, {"bottom", s.bottom_ms}, {"boxes", s.boxes_ms}};
    out.detail = std::to_string(s.cluster_count) + " clusters, " + std::to_string(s.bottom_levels) +
                 " bottom levels, top level " + std::to_string(s.top_ms) + " ms on the host";
    return out;
}

struct GpuRenderer::Impl {
    cuda::Renderer renderer;
    Impl(const Scene& scene, const SceneGeometry& geometry, const Camera& camera, const RenderOptions& options,
         GpuKernel kernel, const BuildOptions& build, int device)
        : renderer(scene, geometry, camera, options, kernel, build, device) {}
};

GpuRenderer::GpuRenderer(const Scene& scene, const SceneGeometry& geometry, const Camera& camera,
                         const RenderOptions& options, GpuKernel kernel, const BuildOptions& build, int device)
    : impl_(std::make_unique<Impl>(scene, geometry, camera, options, kernel, build, device)) {}
GpuRenderer::~GpuRenderer() = default;

GpuPass GpuRenderer::render_pass() {
    impl_->renderer.render_pass();
    const cuda::PassStats& last = impl_->renderer.last_pass();
    return {last.pass_ms, last.closest_rays, last.shadow_rays};
}

AccelStats GpuRenderer::accel_stats() const { return impl_->renderer.tracer().stats(); }

}  // namespace rf::bench
