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
//    speculative while-while traversal (trace/aila_laine_traversal.h, or its
//    aila-laine-fma variant, trace/aila_laine_fma_traversal.h) and the 2012
//    addendum's dynamic fetch, which refills a warp's terminated lanes once
//    most of them are idle.
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
#include "backend/cuda/cwbvh_fma_trace.h"
#include "backend/cuda/device_builders.h"
#include "backend/cuda/device_bvh.h"
#include "backend/cuda/device_tracer_impl.h"
#include "backend/cuda/event_timer.h"
#include "backend/cuda/kernel_resources.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/layout_convert.h"

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
// kernel once the ray pool is exhausted and it has no ray. Traversal is the
// node-pair traversal's state, begin and resume: AilaLaineTraversal
// (aila-laine) or AilaLaineFmaTraversal (aila-laine-fma).
template <bool kAnyHit, class Traversal = AilaLaineTraversal>
__global__ void aila_laine_persistent_kernel(AilaLaineView bvh, const Ray* rays, Hit* hits, uint8_t* flags,
                                             uint32_t count, uint32_t* next_ray) {
    const uint32_t lane = threadIdx.x & 31u;
    const uint32_t lanes_below = (1u << lane) - 1u;
    typename Traversal::State state;
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
                Traversal::begin(bvh, rays[ray_index], state);
                has_ray = true;
            }
        }
        if (Traversal::template resume<kAnyHit, false, AilaLaineDynamicFetchVote>(bvh, state, nullptr)) {
            if constexpr (kAnyHit) flags[ray_index] = state.hit.found() ? 1 : 0;
            else hits[ray_index] = state.hit;
            has_ray = false;
        }
    }
}

// Instrumented traversal: per-ray counters summed in a warp, one atomic per
// warp; totals: steps, triangle tests, restarts, node fetches.
template <class Tracer>
__global__ void count_kernel(Tracer tracer, const Ray* rays, uint32_t count, bool any_hit,
                             unsigned long long* totals) {
    for (uint32_t base = blockIdx.x * blockDim.x; base < count; base += gridDim.x * blockDim.x) {
        const uint32_t i = base + threadIdx.x;
        RayCounters c;
        if (i < count) (void)tracer.counted(rays[i], any_hit, c);
        unsigned long long steps = c.steps, tests = c.prim_tests, restarts = c.restarts, fetches = c.node_fetches;
        for (int offset = 16; offset > 0; offset >>= 1) {
            steps += __shfl_down_sync(0xFFFFFFFFu, steps, offset);
            tests += __shfl_down_sync(0xFFFFFFFFu, tests, offset);
            restarts += __shfl_down_sync(0xFFFFFFFFu, restarts, offset);
            fetches += __shfl_down_sync(0xFFFFFFFFu, fetches, offset);
        }
        if ((threadIdx.x & 31u) == 0) {
            atomicAdd(&totals[0], steps);
            atomicAdd(&totals[1], tests);
            atomicAdd(&totals[2], restarts);
            atomicAdd(&totals[3], fetches);
        }
    }
}

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// Blocks of the node-pair persistent kernel that fit one multiprocessor,
// closest hit and any hit.
template <class Traversal>
void persistent_blocks_per_sm(int (&per_sm)[2]) {
    RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
        &per_sm[0], aila_laine_persistent_kernel<false, Traversal>, kTraceBlock, 0));
    RF_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
        &per_sm[1], aila_laine_persistent_kernel<true, Traversal>, kTraceBlock, 0));
}

// The persistent kernel's grid sizes (enough warps to fill every
// multiprocessor), closest and any hit, queried once whatever thread asks.
void query_persistent_blocks(DeviceTracer::Impl& impl) {
    if (!uses_ray_counter(impl.kernel)) return;
    std::call_once(impl.persistent_once, [&] {
        int per_sm[2] = {0, 0};
        if (impl.kernel == GpuKernel::CwbvhFma) {
            for (int any_hit = 0; any_hit < 2; ++any_hit) per_sm[any_hit] = cwbvh_fma_blocks_per_sm(any_hit != 0);
        } else if (impl.kernel == GpuKernel::AilaLaineFma) {
            persistent_blocks_per_sm<AilaLaineFmaTraversal>(per_sm);
        } else {
            persistent_blocks_per_sm<AilaLaineTraversal>(per_sm);
        }
        for (int i = 0; i < 2; ++i) impl.persistent_blocks[i] = std::max(1, per_sm[i]) * impl.multiprocessors;
    });
}

// Work done before the bench's timed launch, so that it is not timed: the
// persistent kernel's ray counter is reset and its grid size known.
void prepare_trace(DeviceTracer::Impl& impl) {
    if (!uses_ray_counter(impl.kernel)) return;
    impl.work_counter.reserve(1);
    RF_CUDA_CHECK(cudaMemset(impl.work_counter.data(), 0, sizeof(uint32_t)));
    query_persistent_blocks(impl);
}

// The node-pair persistent kernel over `bvh` with Traversal (its grid size known).
template <class Traversal>
void launch_aila_laine_persistent(const DeviceTracer::Impl& impl, const AilaLaineView& bvh, bool any_hit,
                                  uint32_t count, const TraceTarget& t) {
    const LaunchShape persistent{uint32_t(impl.persistent_blocks[any_hit ? 1 : 0]), kTraceBlock};
    if (any_hit)
        launch_shaped_on(t.stream, aila_laine_persistent_kernel<true, Traversal>, persistent, bvh, t.rays, nullptr,
                         t.flags, count, t.counter);
    else
        launch_shaped_on(t.stream, aila_laine_persistent_kernel<false, Traversal>, persistent, bvh, t.rays, t.hits,
                         nullptr, count, t.counter);
}

// Launches the trace of `count` rays with the kernel's scheduling (the
// persistent grid size known).
void launch_trace(const DeviceTracer::Impl& impl, bool any_hit, uint32_t count, const TraceTarget& t) {
    if (impl.kernel == GpuKernel::CwbvhFma) {
        launch_cwbvh_fma_trace(impl, any_hit, count, t);
        return;
    }
    if (impl.kernel == GpuKernel::AilaLaine) {
        launch_aila_laine_persistent<AilaLaineTraversal>(impl, impl.aila_laine.bvh, any_hit, count, t);
        return;
    }
    if (impl.kernel == GpuKernel::AilaLaineFma) {
        launch_aila_laine_persistent<AilaLaineFmaTraversal>(impl, impl.aila_laine_fma.bvh, any_hit, count, t);
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
        case GpuKernel::AilaLaine:
        case GpuKernel::AilaLaineFma: {
            const Placed placed = place_aila_laine(impl, bvh, triangles, impl.convert_on_device);
            impl.aila_laine_fma.bvh = impl.aila_laine.bvh;
            return placed;
        }
        case GpuKernel::Cwbvh:
        case GpuKernel::CwbvhFma: {
            const Placed placed = place_cwbvh(impl, bvh, triangles, impl.convert_on_device);
            impl.cwbvh_fma.bvh = impl.cwbvh.bvh;
            return placed;
        }
        default: return place_bvh2(impl, bvh, device_triangles);
    }
}

// The BVH's stats, from its host copy.
void set_bvh_stats(DeviceTracer::Impl& impl, const Bvh& bvh, Builder builder) {
    AccelStats& stats = impl.stats;
    stats.name += "/" + to_string(builder);
    stats.sah_cost = bvh.sah_cost(1.0f, 1.0f);
    stats.quality_cost = bvh.quality_cost(2.0);
    stats.leaf_count = bvh.leaf_count();
}

// A device-resident canonical BVH in the kernel's layout, converted on the
// device straight into the tracer's buffers (bvh2: the tree's own buffers
// taken over). device_triangles: the tracer's.
Placed place_resident_layout(DeviceTracer::Impl& impl, DeviceBvh& bvh, const Triangle* device_triangles,
                             size_t triangle_count) {
    const DeviceCanonicalView view = canonical_view(bvh, device_triangles, triangle_count);
    const auto start = std::chrono::steady_clock::now();
    switch (impl.kernel) {
        case GpuKernel::AilaLaine:
        case GpuKernel::AilaLaineFma: {
            const ResidentAilaLaine al = convert_to_aila_laine_resident(
                view, impl.aila_laine_nodes, impl.aila_laine_triangles, &impl.build_stages.layout_ms, impl.device);
            impl.aila_laine.bvh = {impl.aila_laine_nodes.data(), impl.aila_laine_triangles.data(), al.root,
                                   al.node_count};
            impl.aila_laine_fma.bvh = impl.aila_laine.bvh;
            impl.stats.node_count = al.node_count;
            return {al.memory_bytes(), ms_since(start)};
        }
        case GpuKernel::Cwbvh:
        case GpuKernel::CwbvhFma: {
            const ResidentCwbvh cw = build_cwbvh_resident(view, impl.cwbvh_nodes, impl.cwbvh_triangles,
                                                          &impl.build_stages.layout_ms, impl.device);
            impl.cwbvh.bvh = {impl.cwbvh_nodes.data(), impl.cwbvh_triangles.data(), cw.node_count,
                              cw.triangle_count};
            impl.cwbvh_fma.bvh = impl.cwbvh.bvh;
            impl.stats.node_count = cw.node_count;
            return {cw.memory_bytes(), ms_since(start)};
        }
        default: {
            const uint32_t nodes = view.node_count;
            impl.bvh_nodes = std::move(bvh.nodes);
            impl.prim_indices = std::move(bvh.prim_indices);
            impl.bvh2.bvh = {impl.bvh_nodes.data(), impl.prim_indices.data(), device_triangles, nodes};
            impl.stats.node_count = nodes;
            return {impl.bvh_nodes.bytes() + impl.prim_indices.bytes(), 0.0};
        }
    }
}

// A device build kept on the device (issue 33 item 3): built, converted
// into the tracer's buffers, synchronized: the first ray is possible, and
// first_ray_ms is the host time to here less the triangles' uploads (the
// builder's and the tracer's). Only then does the tree come to the host,
// for the stats.
Placed place_resident_bvh(DeviceTracer::Impl& impl, std::span<const Triangle> triangles, const BuildOptions& build) {
    DeviceBuildStages& stages = impl.build_stages;
    const auto start = std::chrono::steady_clock::now();
    DeviceBvh bvh = build_resident_bvh(triangles, build, stages, impl.device);
    const auto upload_start = std::chrono::steady_clock::now();
    const Triangle* device_triangles = upload_triangles(impl, triangles);
    const double triangle_upload_ms = ms_since(upload_start);
    impl.convert_on_device = true;
    const Placed placed = place_resident_layout(impl, bvh, device_triangles, triangles.size());
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    stages.first_ray_ms = ms_since(start) - stages.upload_ms - triangle_upload_ms;

    Bvh host;
    if (impl.kernel == GpuKernel::Bvh2) {  // the tracer took the tree's buffers
        host.nodes = download_all(impl.bvh_nodes, impl.bvh_nodes.size());
        host.prim_indices = download_all(impl.prim_indices, impl.prim_indices.size());
    } else {
        host = download_bvh(bvh);
    }
    set_bvh_stats(impl, host, build.builder);
    return placed;
}

// A BVH from build.builder (on the device where it has a device builder), in the kernel's layout.
Placed place_bvh(DeviceTracer::Impl& impl, std::span<const Triangle> triangles, const BuildOptions& build,
                 Refittable refittable) {
    const bool device_build = build.build_on_device && has_device_builder(build.builder);
    // A refittable structure keeps its host tree and converts from it (the host chain).
    if (device_build && refittable == Refittable::No) return place_resident_bvh(impl, triangles, build);
    const auto start = std::chrono::steady_clock::now();
    Bvh bvh = device_build ? build_bvh_on_device(triangles, build, &impl.build_stages, impl.device)
                           : build_bvh_on_cpu(triangles, build);
    set_bvh_stats(impl, bvh, build.builder);
    impl.convert_on_device = build.build_on_device;
    if (refittable == Refittable::Yes) {
        impl.refitter = std::make_unique<DeviceBvhRefit>(bvh, impl.device);
        (void)impl.refitter->refit(triangles);  // uploads the triangles, recomputes the boxes from them
        if (impl.kernel != GpuKernel::Bvh2) impl.host_bvh = bvh;
    }
    const Placed placed = place_layout(impl, bvh, triangles);
    // Time to first ray on the host chain (refittable): everything after the
    // builder's triangle upload until the traced layout is resident,
    // downloads and re-uploads included.
    if (device_build) {
        RF_CUDA_CHECK(cudaDeviceSynchronize());
        impl.build_stages.first_ray_ms = ms_since(start) - impl.build_stages.upload_ms;
    }
    return placed;
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
    constexpr int kTotals = 4;  // count_kernel's: steps, triangle tests, restarts, node fetches
    impl.totals.reserve(kTotals);
    RF_CUDA_CHECK(cudaMemset(impl.totals.data(), 0, kTotals * sizeof(unsigned long long)));
    impl.with_tracer([&](const auto& tracer) {
        using Tracer = std::decay_t<decltype(tracer)>;
        launch_shaped(count_kernel<Tracer>, trace_shape(count), tracer, impl.rays.data(), count, any_hit,
                      impl.totals.data());
    });
    unsigned long long sums[kTotals] = {0, 0, 0, 0};
    RF_CUDA_CHECK(cudaMemcpy(sums, impl.totals.data(), sizeof sums, cudaMemcpyDeviceToHost));
    totals.rays += count;
    totals.steps += sums[0];
    totals.prim_tests += sums[1];
    totals.restarts += sums[2];
    totals.node_fetches += sums[3];
}

GpuKernel DeviceTracer::kernel() const { return impl_->kernel; }
int DeviceTracer::device() const { return impl_->device; }
AccelStats DeviceTracer::stats() const { return impl_->stats; }
void DeviceTracer::set_stats(const AccelStats& stats) { impl_->stats = stats; }
const DeviceBuildStages& DeviceTracer::build_stages() const { return impl_->build_stages; }

// ---- The bench's per-kernel resources (kernel_resources.cu; added with issue
// 33's bench work). The kernels launch_trace launches for `kernel`, closest
// and any hit, at the block size it launches them with: keep in step with
// launch_trace. The trace kernels live in this file's anonymous namespace,
// hence this function here.
namespace {

template <class Tracer>
void add_grid_stride_resources(std::vector<GpuKernelResources>& out, const std::string& name, int device) {
    out.push_back(kernel_resources_of(reinterpret_cast<const void*>(intersect_kernel<Tracer>),
                                      name + " closest (grid-stride)", int(kTraceBlock), device));
    out.push_back(kernel_resources_of(reinterpret_cast<const void*>(occluded_kernel<Tracer>),
                                      name + " any (grid-stride)", int(kTraceBlock), device));
}

}  // namespace

std::vector<GpuKernelResources> trace_kernel_resources(GpuKernel kernel, int device) {
    using Impl = DeviceTracer::Impl;
    std::vector<GpuKernelResources> out;
    const std::string name = to_string(kernel);
    switch (kernel) {
        case GpuKernel::AilaLaine:
            out.push_back(kernel_resources_of(reinterpret_cast<const void*>(aila_laine_persistent_kernel<false>),
                                              name + " closest (persistent)", int(kTraceBlock), device));
            out.push_back(kernel_resources_of(reinterpret_cast<const void*>(aila_laine_persistent_kernel<true>),
                                              name + " any (persistent)", int(kTraceBlock), device));
            break;
        case GpuKernel::CwbvhFma: out = cwbvh_fma_kernel_resources(device); break;
        case GpuKernel::Bvh2: add_grid_stride_resources<decltype(Impl::bvh2)>(out, name, device); break;
        case GpuKernel::AilaLaineFma:
            out.push_back(kernel_resources_of(
                reinterpret_cast<const void*>(aila_laine_persistent_kernel<false, AilaLaineFmaTraversal>),
                name + " closest (persistent)", int(kTraceBlock), device));
            out.push_back(kernel_resources_of(
                reinterpret_cast<const void*>(aila_laine_persistent_kernel<true, AilaLaineFmaTraversal>),
                name + " any (persistent)", int(kTraceBlock), device));
            break;
        case GpuKernel::Cwbvh: add_grid_stride_resources<decltype(Impl::cwbvh)>(out, name, device); break;
        case GpuKernel::KdShortStack:
            add_grid_stride_resources<decltype(Impl::kd_short_stack)>(out, name, device);
            break;
        case GpuKernel::KdRestart: add_grid_stride_resources<decltype(Impl::kd_restart)>(out, name, device); break;
        case GpuKernel::Grid:
        case GpuKernel::ProximityGrid: add_grid_stride_resources<decltype(Impl::grid)>(out, name, device); break;
    }
    return out;
}


}  // namespace rf::cuda
