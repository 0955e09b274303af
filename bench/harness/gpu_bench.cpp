// gpu_bench.h on the CUDA backend: thin forwards to rf::cuda (compiled only
// when the backend is built; gpu_bench_missing.cpp stands in otherwise).
#include "gpu_bench.h"

#include "rayforge/backend/cuda.h"
#include <limits>
#include <utility>

#include "accel/bvh/layout/aila_laine_layout.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel/grid/uniform_grid.h"
#include "rayforge/backend/cuda_build.h"
#include "rayforge/core/error.h"

namespace rf::bench {

bool gpu_bench_available() { return true; }

void require_gpu_device(int device) { cuda::require_device(device); }

std::string gpu_device_name(int device) {
    for (const cuda::DeviceInfo& info : cuda::list_devices().devices)
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

double sah_of(const Bvh& bvh) { return bvh.nodes.empty() ? 0.0 : bvh.sah_cost(); }

}  // namespace

GpuBuildStages GpuTracer::build_stages() const {
    const AccelStats stats = impl_->tracer.stats();
    return describe_device_build(impl_->tracer.build_stages(), stats.node_count, stats.sah_cost);
}

GpuBuildStages gpu_build(std::span<const Triangle> triangles, const BuildOptions& options, int device,
                         Bvh* bvh_out) {
    cuda::DeviceBuildStages s;
    Bvh bvh = cuda::build_bvh_on_device(triangles, options, &s, device);
    GpuBuildStages out = describe_device_build(s, bvh.nodes.size(), sah_of(bvh));
    if (bvh_out) *bvh_out = std::move(bvh);
    return out;
}

GpuBuildStages gpu_build_grid(std::span<const Triangle> triangles, int resolution, bool proximity, int device) {
    cuda::DeviceBuildStages s;
    const UniformGrid grid = cuda::build_uniform_grid_on_device(triangles, resolution, proximity, &s, device);
    s.on_device = true;
    GpuBuildStages out = describe_device_build(s, grid.cell_count(), std::numeric_limits<double>::quiet_NaN());
    out.detail += (out.detail.empty() ? "" : ", ") + std::to_string(grid.non_empty_cells()) + " non-empty cells";
    return out;
}

GpuBuildStages gpu_convert_layout(const Bvh& bvh, std::span<const Triangle> triangles, GpuKernel kernel, int device) {
    cuda::DeviceBuildStages s;
    s.on_device = true;
    size_t nodes = 0;
    if (kernel == GpuKernel::AilaLaine) {
        nodes = cuda::convert_to_aila_laine_on_device(bvh, triangles, &s.layout_ms, device).nodes.size();
    } else if (kernel == GpuKernel::Cwbvh) {
        nodes = cuda::build_cwbvh_on_device(bvh, triangles, &s.layout_ms, device).nodes.size();
    } else {
        throw Error("gpu_convert_layout: " + to_string(kernel) + " has no layout conversion");
    }
    GpuBuildStages out = describe_device_build(s, nodes, sah_of(bvh));
    out.device_stages = {{"layout", s.layout_ms}};
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
