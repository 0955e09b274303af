// Scheduling of the cwbvh-fma kernel (GpuKernel::CwbvhFma): persistent
// threads with dynamic fetch, as the Aila-Laine kernel has (Aila and Laine
// 2009, sec. 3; Aila, Laine and Karras 2012), around the resumable
// compressed wide traversal of trace/cwbvh_fma_traversal.h (Ylitie, Karras
// and Laine 2017). Just enough warps to fill the device; each pass, the
// lanes without a ray take new ones with one atomicAdd per warp (a ballot
// counts them, persistent_fetch_ray ranks them), then every lane resumes
// its traversal. A lane steps aside between two iterations of Algorithm 1
// when fewer than kAilaLaineDynamicFetchThreshold lanes are still
// traversing (AilaLaineDynamicFetchVote), so the warp refills its idle
// lanes instead of running nearly empty; it exits once the ray pool is
// exhausted and it has no ray. The lowest kCwbvhSharedStackEntries stack
// entries of every thread live in dynamic shared memory, the rest in local
// memory (CwbvhSharedTopStack).
#include "backend/cuda/cwbvh_fma_trace.h"

#include "backend/cuda/kernel_resources.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/persistent_fetch_steps.h"
#include "trace/aila_laine_traversal.h"
#include "trace/cwbvh_fma_traversal.h"

namespace rf::cuda {

namespace {

// Threads per block (the trace kernels' block size, device_tracer.cu).
constexpr uint32_t kBlock = 128;
// Dynamic shared memory of a block: the stack tops of its threads.
constexpr size_t kSharedStackBytes = size_t(kBlock) * kCwbvhSharedStackEntries * sizeof(detail::CwbvhGroup);

template <bool kAnyHit>
__global__ void __launch_bounds__(kBlock) cwbvh_fma_persistent_kernel(CwbvhView bvh, const Ray* rays, Hit* hits,
                                                                      uint8_t* flags, uint32_t count,
                                                                      uint32_t* next_ray) {
    extern __shared__ detail::CwbvhGroup stack_tops[];
    CwbvhSharedTopStack stack;
    stack.shared = stack_tops + threadIdx.x;
    stack.stride = blockDim.x;
    const uint32_t lane = threadIdx.x & 31u;
    CwbvhFmaRayState state;
    detail::CwbvhNoCount none;
    CwbvhPostponeOnFewActiveLanes postpone;
    AilaLaineDynamicFetchVote vote;
    uint32_t ray_index = 0;
    bool has_ray = false;
    for (;;) {
        const uint32_t active = __activemask();
        const uint32_t needing = __ballot_sync(active, !has_ray);
        if (needing != 0) {
            const int leader = __ffs(needing) - 1;
            uint32_t base = 0;
            if (int(lane) == leader) base = atomicAdd(next_ray, uint32_t(__popc(needing)));
            base = __shfl_sync(active, base, leader);
            if (!has_ray) {
                ray_index = persistent_fetch_ray(base, needing, lane);
                if (ray_index >= count) return;  // nothing left for this lane
                cwbvh_fma_begin(bvh, rays[ray_index], state);
                has_ray = true;
            }
        }
        if (cwbvh_fma_resume<kAnyHit>(bvh, state, stack, &none, &postpone, vote)) {
            if constexpr (kAnyHit) flags[ray_index] = state.hit.found() ? 1 : 0;
            else hits[ray_index] = state.hit;
            has_ray = false;
        }
    }
}

}  // namespace

void launch_cwbvh_fma_trace(const DeviceTracer::Impl& impl, bool any_hit, uint32_t count, const TraceTarget& t) {
    const LaunchShape shape{uint32_t(impl.persistent_blocks[any_hit ? 1 : 0]), kBlock, kSharedStackBytes};
    if (any_hit)
        launch_shaped_on(t.stream, cwbvh_fma_persistent_kernel<true>, shape, impl.cwbvh_fma.bvh, t.rays, nullptr,
                         t.flags, count, t.counter);
    else
        launch_shaped_on(t.stream, cwbvh_fma_persistent_kernel<false>, shape, impl.cwbvh_fma.bvh, t.rays, t.hits,
                         nullptr, count, t.counter);
}

int cwbvh_fma_blocks_per_sm(bool any_hit) {
    int blocks = 0;
    if (any_hit)
        RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, cwbvh_fma_persistent_kernel<true>, kBlock,
                                                                    kSharedStackBytes));
    else
        RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&blocks, cwbvh_fma_persistent_kernel<false>,
                                                                    kBlock, kSharedStackBytes));
    return blocks;
}

std::vector<GpuKernelResources> cwbvh_fma_kernel_resources(int device) {
    const std::string name = to_string(GpuKernel::CwbvhFma);
    return {kernel_resources_of(reinterpret_cast<const void*>(cwbvh_fma_persistent_kernel<false>),
                                name + " closest (persistent)", int(kBlock), device, kSharedStackBytes),
            kernel_resources_of(reinterpret_cast<const void*>(cwbvh_fma_persistent_kernel<true>),
                                name + " any (persistent)", int(kBlock), device, kSharedStackBytes)};
}

}  // namespace rf::cuda
