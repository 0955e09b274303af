// First CUDA kernels: one thread per ray over the canonical BVH, running the
// very traversal and intersection code the CPU backend runs (trace/*.h).
// Faster GPU layouts (Aila-Laine node pairs, CWBVH) come in later issues.
#include <cuda_runtime.h>

#include "backend/cuda/device_buffer.h"
#include "rayforge/backend/cuda.h"
#include "trace/bvh_traversal.h"

namespace rf::cuda {

namespace {

__global__ void intersect_kernel(BvhView bvh, const Ray* rays, Hit* hits, size_t count) {
    for (size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x; i < count; i += size_t(gridDim.x) * blockDim.x)
        hits[i] = bvh_intersect(bvh, rays[i]);
}

__global__ void occluded_kernel(BvhView bvh, const Ray* rays, uint8_t* occluded, size_t count) {
    for (size_t i = blockIdx.x * size_t(blockDim.x) + threadIdx.x; i < count; i += size_t(gridDim.x) * blockDim.x)
        occluded[i] = bvh_occluded(bvh, rays[i]) ? 1 : 0;
}

constexpr int kBlockSize = 128;

int grid_size(size_t count) {
    size_t blocks = (count + kBlockSize - 1) / kBlockSize;
    return int(blocks < 65535 * 32 ? blocks : 65535 * 32);
}

}  // namespace

struct BvhTracer::Impl {
    int device = 0;
    DeviceBuffer<BvhNode> nodes{"bvh nodes", 0};
    DeviceBuffer<uint32_t> prim_indices{"bvh primitive indices", 0};
    DeviceBuffer<Triangle> triangles{"triangles", 0};
    mutable DeviceBuffer<Ray> rays{"rays", 0};
    mutable DeviceBuffer<Hit> hits{"hits", 0};
    mutable DeviceBuffer<uint8_t> flags{"occlusion flags", 0};

    BvhView view() const {
        return {nodes.data(), prim_indices.data(), triangles.data(), uint32_t(nodes.size())};
    }
};

BvhTracer::BvhTracer(const Bvh& bvh, std::span<const Triangle> triangles, int device) : impl_(new Impl) {
    impl_->device = device;
    RF_CUDA_CHECK(cudaSetDevice(device));
    impl_->nodes.upload(bvh.nodes);
    impl_->prim_indices.upload(bvh.prim_indices);
    impl_->triangles.upload(triangles);
}

BvhTracer::~BvhTracer() = default;

void BvhTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (rays.size() != hits.size()) throw Error("cuda::BvhTracer::intersect: rays and hits differ in size");
    if (rays.empty()) return;
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
    if (impl_->hits.size() < rays.size()) impl_->hits.allocate(rays.size());
    intersect_kernel<<<grid_size(rays.size()), kBlockSize>>>(impl_->view(), impl_->rays.data(), impl_->hits.data(),
                                                             rays.size());
    RF_CUDA_CHECK(cudaGetLastError());
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    impl_->hits.download(hits);
}

void BvhTracer::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    if (rays.size() != occluded.size()) throw Error("cuda::BvhTracer::occluded: rays and flags differ in size");
    if (rays.empty()) return;
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
    if (impl_->flags.size() < rays.size()) impl_->flags.allocate(rays.size());
    occluded_kernel<<<grid_size(rays.size()), kBlockSize>>>(impl_->view(), impl_->rays.data(), impl_->flags.data(),
                                                            rays.size());
    RF_CUDA_CHECK(cudaGetLastError());
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    impl_->flags.download(occluded);
}

size_t BvhTracer::device_bytes() const {
    return impl_->nodes.bytes() + impl_->prim_indices.bytes() + impl_->triangles.bytes() + impl_->rays.bytes() +
           impl_->hits.bytes() + impl_->flags.bytes();
}

}  // namespace rf::cuda
