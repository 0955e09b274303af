// DeviceTwoLevel (two_level_trace.h): the arrays of a two-level structure
// uploaded as they are (one buffer per mesh for its nodes, prim indices and
// triangles; a table of per-mesh BvhViews holding the device pointers), and
// one thread per ray (grid-stride loop) running TwoLevelBvh2Tracer.
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
    DeviceBuffer<BvhView> views{"two-level: bottom-level views"};
    DeviceBuffer<BvhNode> top_nodes{"two-level: top nodes"};
    DeviceBuffer<uint32_t> top_prims{"two-level: top prim indices"};
    DeviceBuffer<TwoLevelInstance> instances{"two-level: instances"};
    TwoLevelBvh2Tracer tracer;
    mutable DeviceBuffer<Ray> rays{"two-level: rays"};
    mutable DeviceBuffer<Hit> hits{"two-level: hits"};
    mutable DeviceBuffer<uint8_t> flags{"two-level: occluded flags"};
};

DeviceTwoLevel::DeviceTwoLevel(int device, std::span<const Bvh> blas, std::span<const std::vector<Triangle>> triangles,
                               const Bvh& top, std::span<const TwoLevelInstance> instances)
    : impl_(std::make_unique<Impl>()) {
    if (blas.size() != triangles.size())
        throw Error("two-level device upload: " + std::to_string(blas.size()) + " bottom levels but " +
                    std::to_string(triangles.size()) + " triangle arrays");
    Impl& d = *impl_;
    d.device = device;
    RF_CUDA_CHECK(cudaSetDevice(device));
    std::vector<BvhView> views(blas.size());
    for (size_t m = 0; m < blas.size(); ++m) {
        const std::string mesh = "two-level: mesh " + std::to_string(m);
        d.blas_nodes.emplace_back(mesh + " nodes");
        d.blas_prims.emplace_back(mesh + " prim indices");
        d.blas_triangles.emplace_back(mesh + " triangles");
        d.blas_nodes.back().upload(blas[m].nodes);
        d.blas_prims.back().upload(blas[m].prim_indices);
        d.blas_triangles.back().upload(triangles[m]);
        views[m] = BvhView{d.blas_nodes.back().data(), d.blas_prims.back().data(), d.blas_triangles.back().data(),
                           uint32_t(blas[m].nodes.size())};
    }
    d.views.upload(views);
    d.top_nodes.upload(top.nodes);
    d.top_prims.upload(top.prim_indices);
    d.instances.upload(instances);
    d.tracer = TwoLevelBvh2Tracer{TwoLevelView<BvhView>{d.top_nodes.data(), d.top_prims.data(),
                                                        uint32_t(top.nodes.size()), d.instances.data(), d.views.data()}};
}

DeviceTwoLevel::~DeviceTwoLevel() = default;

void DeviceTwoLevel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (rays.size() != hits.size()) throw Error("two-level device intersect: rays and hits differ in count");
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
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
    impl_->flags.reserve(rays.size());
    const auto count = uint32_t(rays.size());
    launch_shaped(two_level_occluded_kernel, trace_shape(count), impl_->tracer, impl_->rays.data(),
                  impl_->flags.data(), count);
    impl_->flags.download(occluded);
}

}  // namespace rf::cuda
