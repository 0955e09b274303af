// The CUDA backend's rf::Renderer: progressive rendering on one device, the
// films accumulated in device memory.
//
// The path tracer is the wavefront of render/wavefront.h (Laine, Karras and
// Aila 2013), the loop the CPU runs too; here each stage is one kernel
// launch with one thread per item over the shared per-item steps, all
// pixels' paths in one chunk. Only the extension and connection kernels
// trace, so only they depend on the GPU kernel (tracer) chosen. Queues are
// appended to with one atomic per warp (ballot and popc), as the
// dissertation's work queues do. With sort_rays the active queue is sorted
// by the ray key of Garanzha and Loop 2010 (render/ray_sort_key.h) with
// CUB's radix sort before each extension, so neighbouring threads trace
// similar rays. The extension and connection launches are timed with CUDA
// events read after the pass (PassStats::trace_ms: the trace share of a
// pass, apart from shading, compaction and sorting).
//
// Whitted, AO and normals run one thread per pixel (pixel_kernels.h) over
// render/pixel_sample.h, the CPU's per-pixel function.
#include <cuda_runtime.h>

#include <cub/device/device_radix_sort.cuh>

#include <algorithm>
#include <type_traits>
#include <vector>

#include "backend/backends.h"
#include "backend/cuda/cub_run.h"
#include "backend/cuda/cuda_accel.h"
#include "backend/cuda/device_scene.h"
#include "backend/cuda/device_tracer_impl.h"
#include "backend/cuda/display_image.h"
#include "backend/cuda/launch.h"
#include "backend/cuda/pixel_kernels.h"
#include "rayforge/core/error.h"
#include "render/renderer_base.h"
#include "render/wavefront.h"

namespace rf::cuda {

namespace {

// Threads per block of the render kernels: their per-thread state (a path,
// Whitted's ray stack) is large, so blocks stay small.
constexpr uint32_t kRenderBlock = 128;

LaunchShape render_shape(uint32_t items) { return {blocks_for(items, kRenderBlock), kRenderBlock}; }

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

__global__ void generate_kernel(IntegratorSettings s, uint32_t sample, WavefrontQueues q, uint32_t count) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < count) wavefront_generate(s, sample, 0, q, i);
}

__global__ void sort_keys_kernel(IntegratorSettings s, WavefrontQueues q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < count) wavefront_sort_key(s, q, k);
}

template <class Tracer>
__global__ void extend_kernel(Tracer tracer, SceneView view, WavefrontQueues q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < count) wavefront_extend(tracer, view, q, k);
}

__global__ void shade_kernel(SceneView view, PathSettings settings, WavefrontQueues q, uint32_t count) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    if (k < count) wavefront_shade(view, settings, q, k);
}

// Compaction: surviving paths into next_active, shadow connections into
// shadow_slots; counters = [next active count, shadow count].
__global__ void compact_kernel(WavefrontQueues q, uint32_t count, uint32_t* counters) {
    const uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
    const bool in_range = k < count;
    const bool alive = in_range && q.goes_on[k];
    const uint32_t slot = warp_append(&counters[0], alive);
    if (alive) q.next_active[slot] = q.active[k];
    const bool shadow = in_range && q.has_shadow[k];
    const uint32_t shadow_slot = warp_append(&counters[1], shadow);
    if (shadow) q.shadow_slots[shadow_slot] = k;
}

template <class Tracer>
__global__ void connect_kernel(Tracer tracer, SceneView view, WavefrontQueues q, uint32_t count) {
    const uint32_t j = blockIdx.x * blockDim.x + threadIdx.x;
    if (j < count) wavefront_connect(tracer, view, q, j);
}

__global__ void accumulate_kernel(WavefrontQueues q, uint32_t count, float clamp, Films films) {
    const uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
    if (i < count) wavefront_accumulate(q, i, clamp, films);
}

// The wavefront's device buffers, one slot per pixel.
struct WavefrontBuffers {
    DeviceBuffer<PathState> paths{"path states"};
    DeviceBuffer<FirstHitAovs> aovs{"first-hit AOVs"};
    DeviceBuffer<uint32_t> active{"active path queue"}, next_active{"next active path queue"};
    DeviceBuffer<uint32_t> keys{"ray sort keys"}, sorted_keys{"sorted ray keys"};
    DeviceBuffer<PathHit> found{"extension hits"};
    DeviceBuffer<ShadowConnection> shadows{"shadow connections"};
    DeviceBuffer<uint8_t> has_shadow{"shadow flags"}, goes_on{"path survival flags"};
    DeviceBuffer<uint32_t> shadow_slots{"shadow queue"};
    DeviceBuffer<uint32_t> counters{"queue counters"};
    DeviceBuffer<unsigned char> sort_scratch{"radix sort scratch"};

    void allocate(uint32_t n, bool with_aovs, bool sorting) {
        paths.allocate(n);
        aovs.allocate(with_aovs ? n : 0);
        active.allocate(n);
        next_active.allocate(n);
        keys.allocate(sorting ? n : 0);
        sorted_keys.allocate(sorting ? n : 0);
        found.allocate(n);
        shadows.allocate(n);
        has_shadow.allocate(n);
        goes_on.allocate(n);
        shadow_slots.allocate(n);
        counters.allocate(2);
    }
    [[nodiscard]] WavefrontQueues queues() const {
        return {paths.data(),   aovs.size() ? aovs.data() : nullptr,
                active.data(),  next_active.data(),
                keys.data(),    found.data(),
                shadows.data(), has_shadow.data(),
                goes_on.data(), shadow_slots.data()};
    }
};

// The kernel time of a pass's trace launches (extension and shadow
// connections; PassStats::trace_ms): an event recorded before and after each
// on the default stream, read once the pass has finished, so no launch waits
// for the host. Events are made as needed and kept for the next passes.
class TraceLaunchTimer {
public:
    TraceLaunchTimer() = default;
    TraceLaunchTimer(const TraceLaunchTimer&) = delete;
    TraceLaunchTimer& operator=(const TraceLaunchTimer&) = delete;
    ~TraceLaunchTimer() {
        for (cudaEvent_t event : events_) cudaEventDestroy(event);
    }

    void begin_pass() { recorded_ = 0; }
    void start() { record(); }
    void stop() { record(); }
    // The sum of every start-stop interval of the pass; after the pass's synchronisation.
    [[nodiscard]] double total_ms() const {
        double sum = 0.0;
        for (size_t i = 0; i + 1 < recorded_; i += 2) {
            float ms = 0.0f;
            RF_CUDA_CHECK(cudaEventElapsedTime(&ms, events_[i], events_[i + 1]));
            sum += double(ms);
        }
        return sum;
    }

private:
    void record() {
        if (recorded_ == events_.size()) {
            cudaEvent_t event = nullptr;
            RF_CUDA_CHECK(cudaEventCreate(&event));
            events_.push_back(event);
        }
        RF_CUDA_CHECK(cudaEventRecord(events_[recorded_++]));
    }

    std::vector<cudaEvent_t> events_;
    size_t recorded_ = 0;
};

// The device side of run_wavefront: each stage one launch over its items.
class DeviceWavefront {
public:
    DeviceWavefront(const DeviceTracer::Impl& tracer, const SceneView& view, const IntegratorSettings& settings,
                    uint32_t sample, const Films& films, WavefrontBuffers& buffers, TraceLaunchTimer& trace_timer)
        : tracer_(tracer), view_(view), settings_(settings), sample_(sample), films_(films), b_(buffers),
          trace_timer_(trace_timer) {}

    void generate(uint32_t count) {
        launch_shaped(generate_kernel, render_shape(count), settings_, sample_, b_.queues(), count);
    }
    void sort(uint32_t active) {
        launch_shaped(sort_keys_kernel, render_shape(active), settings_, b_.queues(), active);
        cub_run(b_.sort_scratch, [&](void* temp, size_t& bytes) {
            return cub::DeviceRadixSort::SortPairs(temp, bytes, b_.keys.data(), b_.sorted_keys.data(),
                                                   b_.active.data(), b_.next_active.data(), int(active));
        });
        std::swap(b_.active, b_.next_active);
    }
    void extend(uint32_t active) {
        trace_timer_.start();
        tracer_.with_tracer([&](const auto& t) {
            using Tracer = std::decay_t<decltype(t)>;
            launch_shaped(extend_kernel<Tracer>, render_shape(active), t, view_, b_.queues(), active);
        });
        trace_timer_.stop();
        closest_rays += active;
    }
    void shade(uint32_t active) {
        launch_shaped(shade_kernel, render_shape(active), view_, settings_.path, b_.queues(), active);
    }
    WaveSizes compact(uint32_t active) {
        RF_CUDA_CHECK(cudaMemset(b_.counters.data(), 0, 2 * sizeof(uint32_t)));
        launch_shaped(compact_kernel, render_shape(active), b_.queues(), active, b_.counters.data());
        uint32_t sizes[2] = {0, 0};
        RF_CUDA_CHECK(cudaMemcpy(sizes, b_.counters.data(), sizeof sizes, cudaMemcpyDeviceToHost));
        return {sizes[0], sizes[1]};
    }
    void connect(uint32_t shadows) {
        trace_timer_.start();
        tracer_.with_tracer([&](const auto& t) {
            using Tracer = std::decay_t<decltype(t)>;
            launch_shaped(connect_kernel<Tracer>, render_shape(shadows), t, view_, b_.queues(), shadows);
        });
        trace_timer_.stop();
        shadow_rays += shadows;
    }
    void swap_queues() { std::swap(b_.active, b_.next_active); }
    void accumulate(uint32_t count) {
        launch_shaped(accumulate_kernel, render_shape(count), b_.queues(), count, settings_.clamp, films_);
    }

    uint64_t closest_rays = 0, shadow_rays = 0;

private:
    const DeviceTracer::Impl& tracer_;
    const SceneView& view_;
    const IntegratorSettings& settings_;
    uint32_t sample_;
    Films films_;
    WavefrontBuffers& b_;
    TraceLaunchTimer& trace_timer_;
};

const DeviceTracer& device_tracer_of(const Accel& accel) {
    const auto* cuda_accel = dynamic_cast<const CudaAccel*>(&accel);
    if (!cuda_accel) throw Error("render on a CUDA device: the acceleration structure is not a CUDA one");
    return cuda_accel->tracer();
}

class CudaRenderer final : public RendererBase {
public:
    CudaRenderer(std::shared_ptr<WorldCore> world, const Camera& camera, const RenderOptions& options)
        : RendererBase(std::move(world), camera, options) {
        RF_CUDA_CHECK(cudaSetDevice(device().index));
        start();
    }

    [[nodiscard]] std::unique_ptr<DisplayImage> make_display_image() const override {
        return std::make_unique<DeviceDisplayImage>(device().index);
    }

    void update_display(DisplayImage& display, const ToneMapping& tone) const override {
        auto* image = dynamic_cast<DeviceDisplayImage*>(&display);
        if (!image || !(image->device() == device()))
            throw Error("update_display: the display image is not one of " + to_string(device()) +
                        " (make it with this renderer)");
        const float scale = passes() > 0 ? 1.0f / float(passes()) : 0.0f;  // film_mean's scale
        image->assign(color_.data(), scale, options().width, options().height, tone);
    }

private:
    // One pass is a few launches: a cancel is seen before they start.
    bool run_pass(const ProgressCallback&, std::vector<TracedRay>*, const std::atomic<bool>* cancel,
                  PassStats& stats) override {
        if (cancel && cancel->load(std::memory_order_relaxed)) return false;
        RF_CUDA_CHECK(cudaSetDevice(device().index));
        const bool path = options().integrator == IntegratorKind::Path;
        if (path) path_pass(stats);
        else pixel_pass(stats);
        RF_CUDA_CHECK(cudaDeviceSynchronize());
        if (path) stats.trace_ms = trace_timer_.total_ms();
        return true;
    }

    void path_pass(PassStats& stats) {
        const uint32_t pixels = uint32_t(options().width) * uint32_t(options().height);
        trace_timer_.begin_pass();
        DeviceWavefront wavefront(tracer_->impl(), scene_->view(), settings(), uint32_t(passes()), films(),
                                  wavefront_, trace_timer_);
        run_wavefront(wavefront, settings(), pixels, stats.waves);
        stats.closest_rays = wavefront.closest_rays;
        stats.shadow_rays = wavefront.shadow_rays;
    }

    void pixel_pass(PassStats& stats) {
        ray_counts_.reserve(2);
        RF_CUDA_CHECK(cudaMemset(ray_counts_.data(), 0, 2 * sizeof(unsigned long long)));
        const PixelPass p{scene_->view(), settings(), uint32_t(passes()), films(), ray_counts_.data()};
        launch_pixel_kernel(tracer_->impl(), p, render_shape(uint32_t(options().width) * uint32_t(options().height)));
        unsigned long long counted[2] = {0, 0};
        RF_CUDA_CHECK(cudaMemcpy(counted, ray_counts_.data(), sizeof(counted), cudaMemcpyDeviceToHost));
        stats.closest_rays = counted[0];
        stats.shadow_rays = counted[1];
    }

    [[nodiscard]] Films films() const {
        if (albedo_.size() == 0) return {color_.data(), nullptr, nullptr, nullptr};
        return {color_.data(), albedo_.data(), normal_.data(), depth_.data()};
    }

    [[nodiscard]] Image film_sums(Film film) const override {
        const DeviceBuffer<Vec3f>& sums = film == Film::Color    ? color_
                                          : film == Film::Albedo ? albedo_
                                          : film == Film::Normal ? normal_
                                                                 : depth_;
        if (sums.size() == 0) return {};
        Image image(options().width, options().height);
        sums.download(image.pixels);
        return image;
    }

    void reset_films() override {
        const RenderOptions& o = options();
        const uint32_t n = uint32_t(o.width) * uint32_t(o.height);
        for (DeviceBuffer<Vec3f>* film : {&color_, &albedo_, &normal_, &depth_}) {
            film->allocate((film == &color_ || o.aovs) ? n : 0);
            if (film->size()) RF_CUDA_CHECK(cudaMemset(film->data(), 0, film->bytes()));
        }
        if (o.integrator == IntegratorKind::Path) wavefront_.allocate(n, o.aovs, o.sort_rays);
        else wavefront_ = WavefrontBuffers{};
    }

    void tables_changed() override { scene_ = std::make_unique<DeviceScene>(tables()); }
    // The world's structure after an update or a device rebuild.
    void structure_changed() override { tracer_ = &device_tracer_of(accel()); }

    const DeviceTracer* tracer_ = nullptr;
    std::unique_ptr<DeviceScene> scene_;
    DeviceBuffer<Vec3f> color_{"film"}, albedo_{"albedo film"}, normal_{"normal film"}, depth_{"depth film"};
    WavefrontBuffers wavefront_;
    TraceLaunchTimer trace_timer_;
    DeviceBuffer<unsigned long long> ray_counts_{"ray counters"};
};

}  // namespace

std::unique_ptr<Renderer> make_renderer(std::shared_ptr<WorldCore> world, const Camera& camera,
                                        const RenderOptions& options) {
    require_device(world->device.index);
    return std::make_unique<CudaRenderer>(std::move(world), camera, options);
}

}  // namespace rf::cuda
