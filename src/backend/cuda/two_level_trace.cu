// DeviceTwoLevel (two_level_trace.h): the arrays of a two-level structure
// uploaded as they are (one buffer per mesh for its nodes, prim indices and
// triangles; a table of per-mesh BvhViews holding the device pointers), and
// one thread per ray (grid-stride loop) running TwoLevelBvh2Tracer. A mesh
// or the top level is replaced by copying it again; the view table is
// rewritten only where a mesh's buffers moved. DeviceTracer (and so the
// renderer) traces it through tracer().
#include <cuda_runtime.h>

#include <string>
#include <vector>

#include "backend/cuda/device_buffer.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/two_level_trace.h"
#include "rayforge/core/error.h"

namespace rf::cuda {

namespace {

constexpr uint32_t kTraceBlock = 128;

LaunchShape trace_shape(uint32_t rays) { return {strided_blocks_for(rays, 65535u * 32u, kTraceBlock), kTraceBlock}; }

__global__ void two_level_intersect_kernel(TwoLevelBvh2Tracer tracer, const Ray* rays, Hit* hits, uint32_t count) {
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < count; i += gridDim.x * blockDim.x)
        hits[i] = tracer.intersect(rays[i]);
}

__global__ void two_level_occluded_kernel(TwoLevelBvh2Tracer tracer, const Ray* rays, uint8_t* flags, uint32_t count) {
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < count; i += gridDim.x * blockDim.x)
        flags[i] = tracer.occluded(rays[i]) ? 1 : 0;
}

}  // namespace

struct DeviceTwoLevel::Impl {
    int device = 0;
    std::vector<DeviceBuffer<BvhNode>> blas_nodes;
    std::vector<DeviceBuffer<uint32_t>> blas_prims;
    std::vector<DeviceBuffer<Triangle>> blas_triangles;
    std::vector<BvhView> host_views;  // per mesh, device pointers
    DeviceBuffer<BvhView> views{"two-level: bottom-level views"};
    DeviceBuffer<BvhNode> top_nodes{"two-level: top nodes"};
    DeviceBuffer<uint32_t> top_prims{"two-level: top prim indices"};
    DeviceBuffer<TwoLevelInstance> instances{"two-level: instances"};
    TwoLevelBvh2Tracer tracer;
    mutable DeviceBuffer<Ray> rays{"two-level: rays"};
    mutable DeviceBuffer<Hit> hits{"two-level: hits"};
    mutable DeviceBuffer<uint8_t> flags{"two-level: occluded flags"};
    uint32_t top_node_count = 0;

    void bind() {
        tracer = TwoLevelBvh2Tracer{TwoLevelView<BvhView>{top_nodes.data(), top_prims.data(), top_node_count,
                                                          instances.data(), views.data()}};
    }
};

DeviceTwoLevel::DeviceTwoLevel(int device, size_t mesh_count) : impl_(std::make_unique<Impl>()) {
    Impl& d = *impl_;
    d.device = device;
    RF_CUDA_CHECK(cudaSetDevice(device));
    for (size_t m = 0; m < mesh_count; ++m) {
        const std::string mesh = "two-level: mesh " + std::to_string(m);
        d.blas_nodes.emplace_back(mesh + " nodes");
        d.blas_prims.emplace_back(mesh + " prim indices");
        d.blas_triangles.emplace_back(mesh + " triangles");
    }
    d.host_views.assign(mesh_count, BvhView{});
    d.views.upload(d.host_views);
    d.bind();
}

DeviceTwoLevel::DeviceTwoLevel(int device, std::span<const Bvh> blas, std::span<const std::vector<Triangle>> triangles,
                               const Bvh& top, std::span<const TwoLevelInstance> instances)
    : DeviceTwoLevel(device, blas.size()) {
    if (blas.size() != triangles.size())
        throw Error("two-level device upload: " + std::to_string(blas.size()) + " bottom levels but " +
                    std::to_string(triangles.size()) + " triangle arrays");
    for (size_t m = 0; m < blas.size(); ++m) set_mesh(uint32_t(m), blas[m], triangles[m]);
    set_top(top, instances);
}

void DeviceTwoLevel::set_mesh(uint32_t mesh, const Bvh& blas, std::span<const Triangle> triangles) {
    Impl& d = *impl_;
    if (mesh >= d.host_views.size())
        throw Error("two-level device upload: mesh " + std::to_string(mesh) + " of " +
                    std::to_string(d.host_views.size()));
    RF_CUDA_CHECK(cudaSetDevice(d.device));
    d.blas_nodes[mesh].upload(blas.nodes);
    d.blas_prims[mesh].upload(blas.prim_indices);
    d.blas_triangles[mesh].upload(triangles);
    const BvhView view{d.blas_nodes[mesh].data(), d.blas_prims[mesh].data(), d.blas_triangles[mesh].data(),
                       uint32_t(blas.nodes.size())};
    BvhView& old = d.host_views[mesh];
    if (old.nodes == view.nodes && old.prim_indices == view.prim_indices && old.triangles == view.triangles &&
        old.node_count == view.node_count)
        return;  // same buffers (a refit): the view table stands
    old = view;
    RF_CUDA_CHECK(cudaMemcpy(d.views.data() + mesh, &view, sizeof view, cudaMemcpyHostToDevice));
}

void DeviceTwoLevel::set_top(const Bvh& top, std::span<const TwoLevelInstance> instances) {
    Impl& d = *impl_;
    RF_CUDA_CHECK(cudaSetDevice(d.device));
    d.top_nodes.upload(top.nodes);
    d.top_prims.upload(top.prim_indices);
    d.instances.upload(instances);
    d.top_node_count = uint32_t(top.nodes.size());
    d.bind();
}

const TwoLevelBvh2Tracer& DeviceTwoLevel::tracer() const { return impl_->tracer; }
int DeviceTwoLevel::device() const { return impl_->device; }

size_t DeviceTwoLevel::bytes() const {
    const Impl& d = *impl_;
    size_t bytes = d.views.bytes() + d.top_nodes.bytes() + d.top_prims.bytes() + d.instances.bytes();
    for (size_t m = 0; m < d.host_views.size(); ++m)
        bytes += d.blas_nodes[m].bytes() + d.blas_prims[m].bytes() + d.blas_triangles[m].bytes();
    return bytes;
}

DeviceTwoLevel::~DeviceTwoLevel() = default;

void DeviceTwoLevel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (rays.size() != hits.size()) throw Error("two-level device intersect: rays and hits differ in count");
    if (rays.empty()) return;
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
    impl_->hits.reserve(rays.size());
    const auto count = uint32_t(rays.size());
    launch_shaped(two_level_intersect_kernel, trace_shape(count), impl_->tracer, impl_->rays.data(),
                  impl_->hits.data(), count);
    impl_->hits.download(hits);
}

void DeviceTwoLevel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    if (rays.size() != occluded.size()) throw Error("two-level device occluded: rays and flags differ in count");
    if (rays.empty()) return;
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
    impl_->flags.reserve(rays.size());
    const auto count = uint32_t(rays.size());
    launch_shaped(two_level_occluded_kernel, trace_shape(count), impl_->tracer, impl_->rays.data(),
                  impl_->flags.data(), count);
    impl_->flags.download(occluded);
}

}  // namespace rf::cuda
