// rf::cuda::Renderer: progressive rendering on one device.
//
// The path tracer is a wavefront (Laine, Karras and Aila 2013, "Megakernels
// Considered Harmful"): per pass, a generation kernel starts one path per
// pixel, then while paths are active an extension kernel traces the active
// rays, a shading kernel runs path_stages.h's shade_path on each hit (emission,
// one light sample, the BSDF sample and Russian roulette), a compaction kernel
// gathers the surviving paths and the shadow connections into queues, and a
// connection kernel tests the shadow rays; a final kernel adds each path's
// radiance to the film. Only the extension and connection kernels trace, so
// only they depend on the GPU kernel (tracer) chosen. Queues are appended to
// with one atomic per warp (ballot and popc), as the dissertation's work
// queues do. With sort_rays the active queue is sorted by the ray key of
// Garanzha and Loop 2010 (render/ray_sort_key.h) with CUB's radix sort
// before each extension, so neighbouring threads trace similar rays.
//
// Whitted, AO and normals run one thread per pixel (pixel_kernels.h).
#include <cuda_runtime.h>

#include <cub/device/device_radix_sort.cuh>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "backend/cuda/device_scene.h"
#include "backend/cuda/device_tracer_impl.h"
#include "backend/cuda/pixel_kernels.h"
#include "rayforge/core/error.h"
#include "render/integrators/path.h"
#include "render/integrators/path_stages.h"
#include "render/ray_sort_key.h"
#include "render/texture_lod.h"

namespace rf::cuda {

namespace {

constexpr int kBlock = 128;
using Clock = std::chrono::steady_clock;

int blocks_for(uint32_t count) { return int(std::max<uint32_t>(1, (count + kBlock - 1) / kBlock)); }

// The slot of this thread's item in a queue, with one atomicAdd per warp:
// the warp's votes give each keeping lane its rank among them.
__device__ __forceinline__ uint32_t warp_append(uint32_t* counter, bool keep) {
    const uint32_t active = __activemask();
    const uint32_t votes = __ballot_sync(active, keep);
    const uint32_t lane = threadIdx.x & 31u;
    const int leader = __ffs(active) - 1;
    uint32_t base = 0;
    if (int(lane) == leader && votes != 0) base = atomicAdd(counter, uint32_t(__popc(votes)));
    base = __shfl_sync(active, base, leader);
    return base + uint32_t(__popc(votes & ((1u << lane) - 1u)));
}

struct WavefrontBuffers {
    PathState* paths = nullptr;        // one per pixel, indexed by pixel
    FirstHitAovs* aovs = nullptr;      // one per pixel, or null
    uint32_t* active = nullptr;        // queue of path indices
    uint32_t* next_active = nullptr;
    PathHit* hits = nullptr;           // per active slot
    uint8_t* alive = nullptr;          // per active slot: the path goes on
    ShadowConnection* shadows = nullptr;  // per active slot
    uint8_t* has_shadow = nullptr;     // per active slot
    uint32_t* shadow_queue = nullptr;  // active slots with a shadow connection
    uint32_t* counters = nullptr;      // [0] next active count, [1] shadow count
};

__global__ void generate_kernel(CameraFrame camera, int width, int height, uint32_t sample, uint32_t seed,
                                PathSettings settings, WavefrontBuffers q) {
    const uint32_t pixel = blockIdx.x * blockDim.x + threadIdx.x;
    const uint32_t count = uint32_t(width) * uint32_t(height);
    if (pixel >= count) return;
    const int x = int(pixel % uint32_t(width)), y = int(pixel / uint32_t(width));
    q.paths[pixel] = generate_camera_path(camera, x, y, width, height, sample, seed, settings);
    if (q.aovs) q.aovs[pixel] = FirstHitAovs{};
    q.active[pixel] = pixel;
}

__global__ void sort_keys_kernel(const PathState* paths, const uint32_t* active, uint32_t count, Box3f bounds,
                                 uint32_t* keys) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < count) keys[k] = ray_sort_key(paths[active[k]].ray, bounds);
}

template <class Tracer>
__global__ void extend_kernel(Tracer tracer, DeviceSceneView view, WavefrontBuffers q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < count) q.hits[k] = extend_path(tracer, view, q.paths[q.active[k]]);
}

__global__ void shade_kernel(DeviceSceneView view, PathSettings settings, WavefrontBuffers q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k >= count) return;
    const uint32_t i = q.active[k];
    ShadowConnection shadow;
    bool has_shadow = false;
    q.alive[k] = shade_path(view, settings, q.paths[i], q.hits[k], q.aovs ? &q.aovs[i] : nullptr, shadow, has_shadow)
                     ? 1
                     : 0;
    q.has_shadow[k] = has_shadow ? 1 : 0;
    if (has_shadow) {
        shadow.path = i;
        q.shadows[k] = shadow;
    }
}

// Compaction: surviving paths into next_active, shadow connections into shadow_queue.
__global__ void compact_kernel(WavefrontBuffers q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    const bool in_range = k < count;
    const bool alive = in_range && q.alive[k];
    const uint32_t slot = warp_append(&q.counters[0], alive);
    if (alive) q.next_active[slot] = q.active[k];
    const bool shadow = in_range && q.has_shadow[k];
    const uint32_t shadow_slot = warp_append(&q.counters[1], shadow);
    if (shadow) q.shadow_queue[shadow_slot] = k;
}

template <class Tracer>
__global__ void connect_kernel(Tracer tracer, DeviceSceneView view, WavefrontBuffers q, uint32_t count) {
    const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
    if (j >= count) return;
    const ShadowConnection& shadow = q.shadows[q.shadow_queue[j]];
    // One connection per path per round: no other thread writes this path now.
    if (connect_shadow(tracer, view, shadow)) q.paths[shadow.path].radiance += shadow.contribution;
}

__global__ void accumulate_paths_kernel(WavefrontBuffers q, uint32_t count, float clamp, Films films) {
    const uint32_t pixel = blockIdx.x * blockDim.x + threadIdx.x;
    if (pixel >= count) return;
    films.color[pixel] += film_sample(q.paths[pixel].radiance, clamp);
    if (q.aovs) {
        const FirstHitAovs& a = q.aovs[pixel];
        films.albedo[pixel] += a.albedo;
        films.normal[pixel] += a.normal;
        films.depth[pixel] += Vec3f(a.depth);
    }
}

Image mean_image(const DeviceBuffer<Vec3f>& sums, int width, int height, int passes) {
    if (sums.size() == 0) return {};
    Image image(width, height);
    sums.download(image.pixels);
    const float scale = passes > 0 ? 1.0f / float(passes) : 0.0f;
    for (Vec3f& p : image.pixels) p = p * scale;
    return image;
}

}  // namespace

struct Renderer::State {
    RenderOptions options;
    CameraFrame frame;
    std::unique_ptr<DeviceTracer> tracer;
    std::unique_ptr<DeviceScene> scene;
    PathSettings path;
    WhittedSettings whitted;
    AoSettings ao;
    Box3f sort_bounds;
    int passes = 0;
    RenderStats stats;
    PassStats last;

    DeviceBuffer<Vec3f> color{"film"}, albedo{"albedo film"}, normal{"normal film"}, depth{"depth film"};
    // Wavefront queues (path integrator only).
    DeviceBuffer<PathState> paths{"path states"};
    DeviceBuffer<FirstHitAovs> aovs{"first-hit AOVs"};
    DeviceBuffer<uint32_t> active{"active path queue"}, next_active{"next active path queue"};
    DeviceBuffer<PathHit> hits{"extension hits"};
    DeviceBuffer<uint8_t> alive{"path survival flags"}, has_shadow{"shadow flags"};
    DeviceBuffer<ShadowConnection> shadows{"shadow connections"};
    DeviceBuffer<uint32_t> shadow_queue{"shadow queue"};
    DeviceBuffer<uint32_t> counters{"queue counters"};
    DeviceBuffer<unsigned long long> ray_counts{"ray counters"};
    DeviceBuffer<uint32_t> sort_keys{"ray sort keys"}, sorted_keys{"sorted ray keys"};
    DeviceBuffer<unsigned char> sort_scratch{"radix sort scratch"};

    [[nodiscard]] uint32_t pixels() const { return uint32_t(options.width) * uint32_t(options.height); }

    Films films() const {
        return {color.data(), albedo.size() ? albedo.data() : nullptr, normal.size() ? normal.data() : nullptr,
                depth.size() ? depth.data() : nullptr};
    }

    WavefrontBuffers queues() const {
        WavefrontBuffers q;
        q.paths = paths.data();
        q.aovs = aovs.size() ? aovs.data() : nullptr;
        q.active = active.data();
        q.next_active = next_active.data();
        q.hits = hits.data();
        q.alive = alive.data();
        q.shadows = shadows.data();
        q.has_shadow = has_shadow.data();
        q.shadow_queue = shadow_queue.data();
        q.counters = counters.data();
        return q;
    }

    void sort_active(uint32_t count) {
        sort_keys_kernel<<<blocks_for(count), kBlock>>>(paths.data(), active.data(), count, sort_bounds,
                                                        sort_keys.data());
        RF_CUDA_CHECK(cudaGetLastError());
        size_t scratch = 0;
        RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, scratch, sort_keys.data(), sorted_keys.data(),
                                                      active.data(), next_active.data(), int(count)));
        sort_scratch.reserve(scratch);
        RF_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(sort_scratch.data(), scratch, sort_keys.data(),
                                                      sorted_keys.data(), active.data(), next_active.data(),
                                                      int(count)));
        std::swap(active, next_active);
    }

    void path_pass() {
        const uint32_t n = pixels();
        generate_kernel<<<blocks_for(n), kBlock>>>(frame, options.width, options.height, uint32_t(passes),
                                                   options.seed, path, queues());
        RF_CUDA_CHECK(cudaGetLastError());
        uint32_t count = n;
        last.paths_per_bounce.clear();
        while (count > 0) {
            last.paths_per_bounce.push_back(count);
            last.closest_rays += count;
            if (options.sort_rays) sort_active(count);
            const WavefrontBuffers q = queues();
            tracer->impl().with_tracer([&](const auto& t) {
                extend_kernel<<<blocks_for(count), kBlock>>>(t, scene->view(), q, count);
            });
            RF_CUDA_CHECK(cudaGetLastError());
            shade_kernel<<<blocks_for(count), kBlock>>>(scene->view(), path, q, count);
            RF_CUDA_CHECK(cudaGetLastError());
            RF_CUDA_CHECK(cudaMemset(counters.data(), 0, 2 * sizeof(uint32_t)));
            compact_kernel<<<blocks_for(count), kBlock>>>(q, count);
            RF_CUDA_CHECK(cudaGetLastError());
            uint32_t sizes[2] = {0, 0};
            RF_CUDA_CHECK(cudaMemcpy(sizes, counters.data(), sizeof sizes, cudaMemcpyDeviceToHost));
            if (sizes[1] > 0) {
                tracer->impl().with_tracer([&](const auto& t) {
                    connect_kernel<<<blocks_for(sizes[1]), kBlock>>>(t, scene->view(), q, sizes[1]);
                });
                RF_CUDA_CHECK(cudaGetLastError());
                last.shadow_rays += sizes[1];
            }
            std::swap(active, next_active);
            count = sizes[0];
        }
        accumulate_paths_kernel<<<blocks_for(n), kBlock>>>(queues(), n, options.max_sample_value, films());
        RF_CUDA_CHECK(cudaGetLastError());
    }

    void pixel_pass() {
        PixelKernelParams p;
        p.view = scene->view();
        p.camera = frame;
        p.width = options.width;
        p.height = options.height;
        p.sample = uint32_t(passes);
        p.seed = options.seed;
        p.centre = options.spp == 1;
        p.integrator = int(options.integrator);
        p.whitted = whitted;
        p.ao = ao;
        p.clamp = options.max_sample_value;
        p.films = films();
        ray_counts.reserve(2);
        RF_CUDA_CHECK(cudaMemset(ray_counts.data(), 0, 2 * sizeof(unsigned long long)));
        p.ray_counts = ray_counts.data();
        launch_pixel_kernel(tracer->impl(), p, blocks_for(pixels()), kBlock);
        unsigned long long counted[2] = {0, 0};
        RF_CUDA_CHECK(cudaMemcpy(counted, ray_counts.data(), sizeof(counted), cudaMemcpyDeviceToHost));
        last.closest_rays += counted[0];
        last.shadow_rays += counted[1];
    }
};

Renderer::Renderer(const Scene& scene, const SceneGeometry& geometry, const Camera& camera,
                   const RenderOptions& options, GpuKernel kernel, const BuildOptions& build, int device)
    : state_(new State) {
    validate_render_options(options);
    State& st = *state_;
    st.options = options;
    st.frame = CameraFrame::make(camera, options.width, options.height);
    st.tracer = std::make_unique<DeviceTracer>(geometry, kernel, build, device);
    {
        const HostSceneView host(scene, geometry);  // mip chains and light tables, built on the CPU
        st.scene = std::make_unique<DeviceScene>(host);
        st.ao = {.samples = options.ao_samples,
                 .radius = options.ao_radius > 0.0f ? options.ao_radius : 0.1f * host.diagonal()};
    }
    st.whitted.reflection_depth = options.reflection_depth;
    st.whitted.refraction_depth = options.refraction_depth;
    st.whitted.shading = int(options.whitted_shading);
    st.path.max_depth = options.max_depth;
    st.path.rr_depth = options.rr_depth;
    st.path.strategy = int(options.light_sampling);
    st.path.pixel_spread = pixel_spread_angle(camera.vfov_degrees * (kPi / 180.0f), options.height);
    st.sort_bounds = geometry.bounds;
    st.sort_bounds.extend(st.frame.eye);

    const uint32_t n = st.pixels();
    auto zeroed = [](DeviceBuffer<Vec3f>& film, uint32_t count) {
        film.allocate(count);
        RF_CUDA_CHECK(cudaMemset(film.data(), 0, film.bytes()));
    };
    zeroed(st.color, n);
    if (options.aovs) {
        zeroed(st.albedo, n);
        zeroed(st.normal, n);
        zeroed(st.depth, n);
    }
    if (options.integrator == IntegratorKind::Path) {
        st.paths.allocate(n);
        if (options.aovs) st.aovs.allocate(n);
        st.active.allocate(n);
        st.next_active.allocate(n);
        st.hits.allocate(n);
        st.alive.allocate(n);
        st.has_shadow.allocate(n);
        st.shadows.allocate(n);
        st.shadow_queue.allocate(n);
        st.counters.allocate(2);
        if (options.sort_rays) {
            st.sort_keys.allocate(n);
            st.sorted_keys.allocate(n);
        }
    }
}

Renderer::~Renderer() = default;

void Renderer::render_pass() {
    State& st = *state_;
    RF_CUDA_CHECK(cudaSetDevice(st.tracer->device()));
    const Clock::time_point start = Clock::now();
    st.last = PassStats{};
    if (st.options.integrator == IntegratorKind::Path) st.path_pass();
    else st.pixel_pass();
    RF_CUDA_CHECK(cudaDeviceSynchronize());
    ++st.passes;
    st.last.pass_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    st.stats.samples += st.pixels();
    st.stats.closest_rays += st.last.closest_rays;
    st.stats.shadow_rays += st.last.shadow_rays;
    st.stats.seconds += st.last.pass_ms * 1e-3;
}

int Renderer::passes() const { return state_->passes; }
const RenderOptions& Renderer::options() const { return state_->options; }
RenderStats Renderer::stats() const { return state_->stats; }
const PassStats& Renderer::last_pass() const { return state_->last; }
const DeviceTracer& Renderer::tracer() const { return *state_->tracer; }

Image Renderer::image() const {
    return mean_image(state_->color, state_->options.width, state_->options.height, state_->passes);
}
Image Renderer::albedo() const {
    return mean_image(state_->albedo, state_->options.width, state_->options.height, state_->passes);
}
Image Renderer::normal() const {
    return mean_image(state_->normal, state_->options.width, state_->options.height, state_->passes);
}
Image Renderer::depth() const {
    return mean_image(state_->depth, state_->options.width, state_->options.height, state_->passes);
}

void render_progressive(Renderer& renderer, const DevicePassCallback& after_pass, const ProgressCallback& progress) {
    const RenderOptions& o = renderer.options();
    const Clock::time_point start = Clock::now();
    while (renderer.passes() < o.spp) {
        renderer.render_pass();
        const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
        if (progress) {
            double done = double(renderer.passes()) / double(o.spp);
            if (o.time_budget_s > 0.0) done = std::max(done, std::min(1.0, elapsed / o.time_budget_s));
            progress(std::min(done, 1.0));
        }
        if (after_pass && !after_pass(renderer)) break;
        if (o.time_budget_s > 0.0 && elapsed >= o.time_budget_s) break;
    }
}

}  // namespace rf::cuda
