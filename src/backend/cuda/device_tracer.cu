// DeviceTracer (device_tracer.h): builds the structure a GPU kernel reads (on the
// device where a device builder exists and BuildOptions::build_on_device is
// set, else on the CPU), converts it to that kernel's layout, uploads it,
// and traces batches of rays in device memory. Per-ray traversal is the
// shared code of src/trace; what is GPU-only here is scheduling:
//  - one thread per ray (grid-stride loop) for every kernel;
//  - for the node-pair BVH, the persistent threads of Aila and Laine 2009
//    (sec. 3): just enough warps to fill the device, taking rays from a
//    global counter with one atomic per warp, so that warps finishing early
//    take more work instead of idling while slow warps finish, with the
//    speculative while-while traversal (trace/aila_laine_traversal.h) and
//    the 2012 addendum's dynamic fetch, which refills a warp's terminated
//    lanes once most of them are idle.
#include <cuda_runtime.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <limits>
#include <type_traits>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/grid/uniform_grid.h"
#include "accel/kdtree/kdtree_build.h"
#include "backend/backends.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_tracer_impl.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/launch.h"

namespace rf::cuda {

namespace {

// Threads per block of the trace kernels, and the grid of the grid-stride ones.
constexpr uint32_t kTraceBlock = 128;

LaunchShape trace_shape(uint32_t rays) { return {strided_blocks_for(rays, 65535u * 32u, kTraceBlock), kTraceBlock}; }

template <class Tracer>
__global__ void intersect_kernel(Tracer tracer, const Ray* rays, Hit* hits, uint32_t count) {
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < count; i += gridDim.x * blockDim.x)
        hits[i] = tracer.intersect(rays[i]);
}

template <class Tracer>
__global__ void occluded_kernel(Tracer tracer, const Ray* rays, uint8_t* flags, uint32_t count) {
    for (uint32_t i = blockIdx.x * blockDim.x + threadIdx.x; i < count; i += gridDim.x * blockDim.x)
        flags[i] = tracer.occluded(rays[i]) ? 1 : 0;
}

// Persistent warps (Aila and Laine 2009) with dynamic fetch (Aila, Laine and
// Karras 2012): each pass, the lanes without a ray take new ones with one
// atomicAdd per warp (a ballot counts them, a prefix popc ranks them), then
// every lane resumes its traversal. A lane leaves the traversal when its ray
// is done or, via AilaLaineDynamicFetchVote, when fewer than
// kAilaLaineDynamicFetchThreshold lanes are still traversing, so the warp
// refills its idle lanes instead of running nearly empty. A lane exits the
// kernel once the ray pool is exhausted and it has no ray.
template <bool kAnyHit>
__global__ void aila_laine_persistent_kernel(AilaLaineView bvh, const Ray* rays, Hit* hits, uint8_t* flags,
                                             uint32_t count, uint32_t* next_ray) {
    const uint32_t lane = threadIdx.x & 31u;
    const uint32_t lanes_below = (1u << lane) - 1u;
    AilaLaineRayState state;
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
                ray_index = base + uint32_t(__popc(needing & lanes_below));
                if (ray_index >= count) return;  // nothing left for this lane
                aila_laine_begin(bvh, rays[ray_index], state);
                has_ray = true;
            }
        }
        if (aila_laine_resume<kAnyHit, false, AilaLaineDynamicFetchVote>(bvh, state, nullptr)) {
            if constexpr (kAnyHit) flags[ray_index] = state.hit.found() ? 1 : 0;
            else hits[ray_index] = state.hit;
            has_ray = false;
        }
    }
}

// Instrumented traversal: per-ray counters summed in a warp, one atomic per warp.
template <class Tracer>
__global__ void count_kernel(Tracer tracer, const Ray* rays, uint32_t count, bool any_hit,
                             unsigned long long* totals) {
    for (uint32_t base = blockIdx.x * blockDim.x; base < count; base += gridDim.x * blockDim.x) {
        const uint32_t i = base + threadIdx.x;
        RayCounters c;
        if (i < count) (void)tracer.counted(rays[i], any_hit, c);
        unsigned long long steps = c.steps, tests = c.prim_tests, restarts = c.restarts;
        for (int offset = 16; offset > 0; offset >>= 1) {
            steps += __shfl_down_sync(0xFFFFFFFFu, steps, offset);
            tests += __shfl_down_sync(0xFFFFFFFFu, tests, offset);
            restarts += __shfl_down_sync(0xFFFFFFFFu, restarts, offset);
        }
        if ((threadIdx.x & 31u) == 0) {
            atomicAdd(&totals[0], steps);
            atomicAdd(&totals[1], tests);
            atomicAdd(&totals[2], restarts);
        }
    }
}

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The persistent kernel's grid sizes (enough warps to fill every
// multiprocessor), closest and any hit, queried once whatever thread asks.
void query_persistent_blocks(DeviceTracer::Impl& impl) {
    if (impl.kernel != GpuKernel::AilaLaine) return;
    std::call_once(impl.persistent_once, [&] {
        int per_sm[2] = {0, 0};
        RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm[0], aila_laine_persistent_kernel<false>,
                                                                   kTraceBlock, 0));
        RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm[1], aila_laine_persistent_kernel<true>,
                                                                   kTraceBlock, 0));
        for (int i = 0; i < 2; ++i) impl.persistent_blocks[i] = std::max(1, per_sm[i]) * impl.multiprocessors;
    });
}

// Work done before the bench's timed launch, so that it is not timed: the
// persistent kernel's ray counter is reset and its grid size known.
void prepare_trace(DeviceTracer::Impl& impl) {
    if (impl.kernel != GpuKernel::AilaLaine) return;
    impl.work_counter.reserve(1);
    RF_CUDA_CHECK(cudaMemset(impl.work_counter.data(), 0, sizeof(uint32_t)));
    query_persistent_blocks(impl);
}

// Where one trace reads and writes: device rays, the answers (hits for
// the closest hit, flags for any hit), the persistent kernel's ray counter
// (reset to 0 before the launch), the stream.
struct TraceTarget {
    const Ray* rays = nullptr;
    Hit* hits = nullptr;
    uint8_t* flags = nullptr;
    uint32_t* counter = nullptr;
    cudaStream_t stream = nullptr;
};

// Launches the trace of `count` rays with the kernel's scheduling (the
// persistent grid size known).
void launch_trace(const DeviceTracer::Impl& impl, bool any_hit, uint32_t count, const TraceTarget& t) {
    if (impl.kernel == GpuKernel::AilaLaine) {
        const LaunchShape persistent{uint32_t(impl.persistent_blocks[any_hit ? 1 : 0]), kTraceBlock};
        if (any_hit)
            launch_shaped_on(t.stream, aila_laine_persistent_kernel<true>, persistent, impl.aila_laine.bvh, t.rays,
                             nullptr, t.flags, count, t.counter);
        else
            launch_shaped_on(t.stream, aila_laine_persistent_kernel<false>, persistent, impl.aila_laine.bvh, t.rays,
                             t.hits, nullptr, count, t.counter);
        return;
    }
    impl.with_tracer([&](const auto& tracer) {
        using Tracer = std::decay_t<decltype(tracer)>;
        if (any_hit)
            launch_shaped_on(t.stream, occluded_kernel<Tracer>, trace_shape(count), tracer, t.rays, t.flags, count);
        else
            launch_shaped_on(t.stream, intersect_kernel<Tracer>, trace_shape(count), tracer, t.rays, t.hits, count);
    });
}

// rf::Error unless `pointer` is memory `device` can address as its own
// (device memory of that device, or managed memory).
void check_device_pointer(const void* pointer, int device, const char* what) {
    cudaPointerAttributes attributes{};
    const cudaError_t status = cudaPointerGetAttributes(&attributes, pointer);
    if (status != cudaSuccess) {
        (void)cudaGetLastError();
        throw Error(std::string("cuda::DeviceTracer::trace_on_device: ") + what + " is not CUDA memory (" +
                    cudaGetErrorString(status) + ")");
    }
    const bool managed = attributes.type == cudaMemoryTypeManaged;
    if (!managed && (attributes.type != cudaMemoryTypeDevice || attributes.device != device)) {
        throw Error(std::string("cuda::DeviceTracer::trace_on_device: ") + what + " is not memory of device cuda:" +
                    std::to_string(device) + (attributes.type == cudaMemoryTypeDevice
                                                  ? " (it is on cuda:" + std::to_string(attributes.device) + ")"
                                                  : " (it is host memory)"));
    }
}

uint32_t checked_ray_count(size_t count) {
    if (count > 0x7FFFFFFFu) throw Error("cuda::DeviceTracer: " + std::to_string(count) + " rays in one batch exceed 2^31");
    return uint32_t(count);
}

// What placing a structure on the device gives back: its host-side size and
// the wall time of its layout conversion.
struct Placed {
    size_t structure_bytes = 0;
    double layout_ms = 0.0;
};

// The tracer's triangles go up after the build: a device builder holds its
// own copy while it runs and frees it before returning, so the two copies
// never coexist.
const Triangle* upload_triangles(DeviceTracer::Impl& impl, std::span<const Triangle> triangles) {
    impl.triangles.upload(triangles);
    return impl.triangles.data();
}

Placed place_bvh2(DeviceTracer::Impl& impl, const Bvh& bvh, const Triangle* device_triangles) {
    impl.bvh_nodes.upload(bvh.nodes);
    impl.prim_indices.upload(bvh.prim_indices);
    impl.bvh2.bvh = {impl.bvh_nodes.data(), impl.prim_indices.data(), device_triangles, uint32_t(bvh.nodes.size())};
    impl.stats.node_count = bvh.nodes.size();
    return {bvh.memory_bytes(), 0.0};
}

// Node pairs (Aila and Laine 2009), converted on the device when asked.
Placed place_aila_laine(DeviceTracer::Impl& impl, const Bvh& bvh, std::span<const Triangle> triangles,
                        bool on_device) {
    const auto start = std::chrono::steady_clock::now();
    const AilaLaineBvh al = on_device ? convert_to_aila_laine_on_device(bvh, triangles, &impl.build_stages.layout_ms,
                                                                        impl.device)
                                      : convert_to_aila_laine(bvh, triangles);
    const double layout_ms = ms_since(start);
    impl.aila_laine_nodes.upload(al.nodes);
    impl.aila_laine_triangles.upload(al.triangles);
    impl.aila_laine.bvh = {impl.aila_laine_nodes.data(), impl.aila_laine_triangles.data(), al.root,
                           uint32_t(al.nodes.size())};
    impl.stats.node_count = al.nodes.size();
    return {al.memory_bytes(), layout_ms};
}

// The compressed 8-wide BVH (Ylitie et al. 2017), built on the device when asked.
Placed place_cwbvh(DeviceTracer::Impl& impl, const Bvh& bvh, std::span<const Triangle> triangles, bool on_device) {
    const auto start = std::chrono::steady_clock::now();
    const CwbvhBvh cw = on_device ? build_cwbvh_on_device(bvh, triangles, &impl.build_stages.layout_ms, impl.device)
                                  : build_cwbvh(bvh, triangles);
    const double layout_ms = ms_since(start);
    impl.cwbvh_nodes.upload(cw.nodes);
    impl.cwbvh_triangles.upload(cw.triangles);
    CwbvhView view = cw.view();
    view.nodes = impl.cwbvh_nodes.data();
    view.triangles = impl.cwbvh_triangles.data();
    impl.cwbvh.bvh = view;
    impl.stats.node_count = cw.nodes.size();
    return {cw.memory_bytes(), layout_ms};
}

// The canonical tree in the kernel's layout (after its build or a refit).
Placed place_layout(DeviceTracer::Impl& impl, const Bvh& bvh, std::span<const Triangle> triangles) {
    if (impl.refitter && impl.kernel == GpuKernel::Bvh2) {  // traced in place, where the refit writes
        const DeviceRefitArrays a = impl.refitter->arrays();
        impl.bvh2.bvh = {a.nodes, a.prim_indices, a.triangles, a.node_count};
        impl.stats.node_count = bvh.nodes.size();
        return {bvh.memory_bytes(), 0.0};
    }
    const Triangle* device_triangles = upload_triangles(impl, triangles);
    switch (impl.kernel) {
        case GpuKernel::AilaLaine: return place_aila_laine(impl, bvh, triangles, impl.convert_on_device);
        case GpuKernel::Cwbvh: return place_cwbvh(impl, bvh, triangles, impl.convert_on_device);
        default: return place_bvh2(impl, bvh, device_triangles);
    }
}

// A BVH from build.builder (on the device where it has a device builder), in the kernel's layout.
Placed place_bvh(DeviceTracer::Impl& impl, std::span<const Triangle> triangles, const BuildOptions& build,
                 Refittable refittable) {
    const bool device_build = build.build_on_device && has_device_builder(build.builder);
    Bvh bvh = device_build ? build_bvh_on_device(triangles, build, &impl.build_stages, impl.device)
                           : build_bvh_on_cpu(triangles, build);
    AccelStats& stats = impl.stats;
    stats.name += "/" + to_string(build.builder);
    stats.sah_cost = bvh.sah_cost(1.0f, 1.0f);
    stats.quality_cost = bvh.quality_cost(2.0);
    stats.leaf_count = bvh.leaf_count();
    impl.convert_on_device = build.build_on_device;
    if (refittable == Refittable::Yes) {
        impl.refitter = std::make_unique<DeviceBvhRefit>(bvh, impl.device);
        (void)impl.refitter->refit(triangles);  // uploads the triangles, recomputes the boxes from them
        if (impl.kernel != GpuKernel::Bvh2) impl.host_bvh = bvh;
    }
    return place_layout(impl, bvh, triangles);
}

// The SAH kd-tree, built on the CPU (it has no device builder).
Placed place_kdtree(DeviceTracer::Impl& impl, std::span<const Triangle> triangles, const BuildOptions& build) {
    const KdTree tree = build_kdtree(triangles, build.sah, build.binned, build.kdtree);
    const Triangle* device_triangles = upload_triangles(impl, triangles);
    impl.kd_nodes.upload(tree.nodes);
    impl.prim_indices.upload(tree.prim_indices);
    const KdTreeView kd{impl.kd_nodes.data(), impl.prim_indices.data(), device_triangles, uint32_t(tree.nodes.size()),
                        tree.bounds, build.kdtree.short_stack_size};
    impl.kd_short_stack.tree = kd;
    impl.kd_restart.tree = kd;
    impl.stats.node_count = tree.nodes.size();
    impl.stats.leaf_count = tree.leaf_count();
    impl.stats.sah_cost = tree.sah_cost(build.sah.traversal, build.sah.intersection);
    return {tree.memory_bytes(), 0.0};
}

// A uniform grid (with proximity clouds for that kernel), built on the device when asked.
Placed place_grid(DeviceTracer::Impl& impl, std::span<const Triangle> triangles, const BuildOptions& build) {
    const bool proximity = impl.kernel == GpuKernel::ProximityGrid;
    const UniformGrid grid =
        build.build_on_device
            ? build_uniform_grid_on_device(triangles, build.grid.resolution, proximity, &impl.build_stages, impl.device)
            : build_uniform_grid(triangles, build.grid.resolution, proximity);
    impl.build_stages.on_device = build.build_on_device;
    const Triangle* device_triangles = upload_triangles(impl, triangles);
    impl.cell_start.upload(grid.cell_start);
    impl.cell_prims.upload(grid.cell_prims);
    impl.proximity.upload(grid.proximity);
    GridView view = grid.view(device_triangles);
    view.cell_start = impl.cell_start.data();
    view.cell_prims = impl.cell_prims.data();
    view.proximity = grid.proximity.empty() ? nullptr : impl.proximity.data();
    impl.grid.grid = view;
    impl.stats.node_count = grid.cell_count();
    impl.stats.leaf_count = grid.non_empty_cells();
    impl.stats.sah_cost = impl.stats.quality_cost = std::numeric_limits<double>::quiet_NaN();
    return {grid.memory_bytes(), 0.0};
}

}  // namespace

DeviceTracer::DeviceTracer(const SceneGeometry& geometry, const BuildOptions& build, Refittable refittable)
    : impl_(new Impl) {
    validate_build_options(build);
    Impl& impl = *impl_;
    impl.kernel = build.gpu_kernel;
    impl.device = build.device.index;
    require_device(impl.device);
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&impl.multiprocessors, cudaDevAttrMultiProcessorCount, impl.device));

    const auto start = std::chrono::steady_clock::now();
    const std::span<const Triangle> triangles(geometry.triangles);
    impl.stats.name = "cuda/" + to_string(impl.kernel);
    Placed placed;
    switch (structure_of(impl.kernel)) {
        case Structure::KdTree: placed = place_kdtree(impl, triangles, build); break;
        case Structure::Grid:
        case Structure::ProximityGrid: placed = place_grid(impl, triangles, build); break;
        default: placed = place_bvh(impl, triangles, build, refittable); break;
    }
    if (refittable == Refittable::Yes && !impl.refitter)
        throw Error("cuda::DeviceTracer: only BVH kernels can be refitted, not " + to_string(impl.kernel));
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    impl.stats.build_ms = ms_since(start);
    impl.stats.layout_ms = placed.layout_ms;
    impl.stats.bytes = placed.structure_bytes;
    impl.stats.device_bytes = impl.structure_bytes();
}

DeviceTracer::DeviceTracer(std::unique_ptr<DeviceTwoLevel> two_level, AccelStats stats) : impl_(new Impl) {
    if (!two_level) throw Error("cuda::DeviceTracer: no two-level structure given");
    Impl& impl = *impl_;
    impl.kernel = GpuKernel::Bvh2;
    impl.device = two_level->device();
    require_device(impl.device);
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    RF_CUDA_CHECK(cudaDeviceGetAttribute(&impl.multiprocessors, cudaDevAttrMultiProcessorCount, impl.device));
    impl.two_level = std::move(two_level);
    impl.stats = std::move(stats);
    impl.stats.device_bytes = impl.structure_bytes();
}

DeviceTracer::~DeviceTracer() = default;

double DeviceTracer::refit(std::span<const Triangle> triangles) {
    Impl& impl = *impl_;
    if (!impl.refitter) throw Error("cuda::DeviceTracer::refit: this structure was not built refittable");
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    const double kernel_ms = impl.refitter->refit(triangles);
    if (impl.kernel != GpuKernel::Bvh2) {
        impl.refitter->download(impl.host_bvh);
        impl.stats.layout_ms = place_layout(impl, impl.host_bvh, triangles).layout_ms;
    }
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    impl.stats.device_bytes = impl.structure_bytes();
    return kernel_ms;
}

DeviceTwoLevel* DeviceTracer::two_level() { return impl_->two_level.get(); }

size_t DeviceTracer::Impl::structure_bytes() const {
    return (refitter ? refitter->bytes() : 0) + (two_level ? two_level->bytes() : 0) + triangles.bytes() + bvh_nodes.bytes() + prim_indices.bytes() + aila_laine_nodes.bytes() +
           aila_laine_triangles.bytes() + cwbvh_nodes.bytes() + cwbvh_triangles.bytes() + kd_nodes.bytes() +
           cell_start.bytes() + cell_prims.bytes() + proximity.bytes();
}

BatchScratch::BatchScratch(int device) {
    RF_CUDA_CHECK(cudaSetDevice(device));
    RF_CUDA_CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
}

BatchScratch::~BatchScratch() {
    if (stream) cudaStreamDestroy(stream);
}

namespace {

// A batch of host rays on a scratch of its own: uploaded, traced and
// downloaded on the scratch's stream (hits for the closest hit, else flags).
void trace_host_batch(DeviceTracer::Impl& impl, std::span<const Ray> rays, Hit* hits, uint8_t* flags) {
    const uint32_t count = checked_ray_count(rays.size());
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    query_persistent_blocks(impl);
    const BatchScratchLease scratch(impl.batch_scratch, impl.device);
    const bool any_hit = hits == nullptr;
    scratch->rays.reserve(count);
    if (any_hit) scratch->flags.reserve(count);
    else scratch->hits.reserve(count);
    const cudaStream_t stream = scratch->stream;
    RF_CUDA_CHECK(cudaMemcpyAsync(scratch->rays.data(), rays.data(), rays.size_bytes(), cudaMemcpyHostToDevice, stream));
    RF_CUDA_CHECK(cudaMemsetAsync(scratch->counter.data(), 0, sizeof(uint32_t), stream));
    launch_trace(impl, any_hit, count,
                 {scratch->rays.data(), scratch->hits.data(), scratch->flags.data(), scratch->counter.data(), stream});
    if (any_hit)
        RF_CUDA_CHECK(cudaMemcpyAsync(flags, scratch->flags.data(), count * sizeof(uint8_t), cudaMemcpyDeviceToHost, stream));
    else
        RF_CUDA_CHECK(cudaMemcpyAsync(hits, scratch->hits.data(), count * sizeof(Hit), cudaMemcpyDeviceToHost, stream));
    RF_CUDA_CHECK(cudaStreamSynchronize(stream));
}

}  // namespace

void DeviceTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    if (rays.size() != hits.size()) throw Error("cuda::DeviceTracer::intersect: rays and hits differ in size");
    if (rays.empty()) return;
    trace_host_batch(*impl_, rays, hits.data(), nullptr);
}

void DeviceTracer::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    if (rays.size() != occluded.size()) throw Error("cuda::DeviceTracer::occluded: rays and flags differ in size");
    if (rays.empty()) return;
    trace_host_batch(*impl_, rays, nullptr, occluded.data());
}

void DeviceTracer::trace_on_device(const Ray* rays, Hit* hits, uint8_t* occluded, size_t count, void* stream) const {
    if (count == 0) return;
    const uint32_t n = checked_ray_count(count);
    Impl& impl = *impl_;
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    check_device_pointer(rays, impl.device, "the rays");
    const bool any_hit = hits == nullptr;
    check_device_pointer(any_hit ? static_cast<const void*>(occluded) : static_cast<const void*>(hits), impl.device,
                         any_hit ? "the occlusion flags" : "the hits");
    const cudaStream_t s = static_cast<cudaStream_t>(stream);
    const cudaError_t usable = cudaStreamQuery(s);
    if (usable != cudaSuccess && usable != cudaErrorNotReady) {
        (void)cudaGetLastError();
        throw Error(std::string("cuda::DeviceTracer::trace_on_device: the stream is not usable on cuda:") +
                    std::to_string(impl.device) + " (" + cudaGetErrorString(usable) + ")");
    }
    query_persistent_blocks(impl);
    const BatchScratchLease scratch(impl.batch_scratch, impl.device);  // the ray counter, this call's own
    RF_CUDA_CHECK(cudaMemsetAsync(scratch->counter.data(), 0, sizeof(uint32_t), s));
    launch_trace(impl, any_hit, n, {rays, hits, occluded, scratch->counter.data(), s});
    RF_CUDA_CHECK(cudaStreamSynchronize(s));
}

void DeviceTracer::upload_rays(std::span<const Ray> rays) {
    (void)checked_ray_count(rays.size());
    RF_CUDA_CHECK(cudaSetDevice(impl_->device));
    impl_->rays.upload(rays);
}

KernelTiming DeviceTracer::trace_uploaded(bool any_hit) {
    Impl& impl = *impl_;
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    const uint32_t count = checked_ray_count(impl.rays.size());
    KernelTiming timing;
    timing.rays = count;
    if (count == 0) return timing;
    if (any_hit) impl.flags.reserve(count);
    else impl.hits.reserve(count);
    prepare_trace(impl);
    EventTimer timer;
    timer.start();
    launch_trace(impl, any_hit, count, {impl.rays.data(), impl.hits.data(), impl.flags.data(), impl.work_counter.data()});
    timing.kernel_ms = timer.stop_ms();
    return timing;
}

void DeviceTracer::download_hits(std::span<Hit> hits) const {
    if (hits.size() > impl_->hits.size()) throw Error("cuda::DeviceTracer: no closest-hit results for that many rays");
    impl_->hits.download(hits);
}

void DeviceTracer::download_occluded(std::span<uint8_t> flags) const {
    if (flags.size() > impl_->flags.size()) throw Error("cuda::DeviceTracer: no any-hit results for that many rays");
    impl_->flags.download(flags);
}

void DeviceTracer::count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const {
    if (rays.empty()) return;
    auto& impl = const_cast<Impl&>(*impl_);
    const uint32_t count = checked_ray_count(rays.size());
    RF_CUDA_CHECK(cudaSetDevice(impl.device));
    impl.rays.upload(rays);
    impl.totals.reserve(3);
    RF_CUDA_CHECK(cudaMemset(impl.totals.data(), 0, 3 * sizeof(unsigned long long)));
    impl.with_tracer([&](const auto& tracer) {
        using Tracer = std::decay_t<decltype(tracer)>;
        launch_shaped(count_kernel<Tracer>, trace_shape(count), tracer, impl.rays.data(), count, any_hit,
                      impl.totals.data());
    });
    unsigned long long sums[3] = {0, 0, 0};
    RF_CUDA_CHECK(cudaMemcpy(sums, impl.totals.data(), sizeof sums, cudaMemcpyDeviceToHost));
    totals.rays += count;
    totals.steps += sums[0];
    totals.prim_tests += sums[1];
    totals.restarts += sums[2];
}

GpuKernel DeviceTracer::kernel() const { return impl_->kernel; }
int DeviceTracer::device() const { return impl_->device; }
AccelStats DeviceTracer::stats() const { return impl_->stats; }
void DeviceTracer::set_stats(const AccelStats& stats) { impl_->stats = stats; }
const DeviceBuildStages& DeviceTracer::build_stages() const { return impl_->build_stages; }


}  // namespace rf::cuda
