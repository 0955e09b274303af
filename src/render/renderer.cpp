// rf::ProgressiveRenderer: each pass adds one sample to every pixel; the
// image is cut into 16x16 tiles rendered in parallel by TBB. Every sample
// draws its random numbers from its own counter-based stream (math/random.h)
// keyed by (pixel, pass, seed), and each pixel's sum is added to in pass
// order, so an image does not depend on the thread count or on which thread
// renders which tile.

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <string>

#include "backend/cpu/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/render/render.h"
#include "render/integrators/ao.h"
#include "render/integrators/normals.h"
#include "render/integrators/path.h"
#include "render/integrators/whitted.h"
#include "math/random.h"
#include "render/scene_view.h"
#include "render/texture_lod.h"
#include "render/wavefront_path.h"

namespace rf {
namespace {

constexpr int kTileSize = 16;
constexpr int kMaxImageSide = 65536;
constexpr size_t kMaxImageBytes = size_t(4) << 30;  // the float RGB film
constexpr int kMaxSpp = 1 << 20;
constexpr int kMaxAoSamples = 1 << 16;
constexpr int kMaxPathDepth = 1024;

using Clock = std::chrono::steady_clock;

static_assert(int(LightSampling::Mis) == kLightSamplingMis && int(LightSampling::Nee) == kLightSamplingNee &&
              int(LightSampling::Bsdf) == kLightSamplingBsdf);
static_assert(int(WhittedShading::Lambert) == kWhittedLambert && int(WhittedShading::Phong) == kWhittedPhong &&
              int(WhittedShading::Blinn) == kWhittedBlinn);

}  // namespace

void validate_render_options(const RenderOptions& o) {
    auto in_range = [](int v, int lo, int hi) { return v >= lo && v <= hi; };
    if (!in_range(o.width, 1, kMaxImageSide) || !in_range(o.height, 1, kMaxImageSide))
        throw Error("render: image size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                    " is outside 1.." + std::to_string(kMaxImageSide));
    const int films = o.aovs ? 4 : 1;  // colour, and albedo, normal, depth
    size_t bytes = size_t(o.width) * size_t(o.height) * sizeof(Vec3f) * size_t(films);
    if (bytes > kMaxImageBytes)
        throw Error("render: a " + std::to_string(o.width) + "x" + std::to_string(o.height) + " film needs " +
                    std::to_string(bytes >> 20) + " MiB, more than the " +
                    std::to_string(kMaxImageBytes >> 20) + " MiB allowed");
    checked_array_bytes("render: " + std::to_string(o.width) + "x" + std::to_string(o.height) + " film",
                        size_t(o.width) * size_t(o.height) * size_t(films), sizeof(Vec3f));
    if (!in_range(o.spp, 1, kMaxSpp))
        throw Error("render: spp must be in 1.." + std::to_string(kMaxSpp) + ", got " + std::to_string(o.spp));
    if (o.threads < 0) throw Error("render: threads must be >= 0, got " + std::to_string(o.threads));
    if (!std::isfinite(o.time_budget_s) || o.time_budget_s < 0.0)
        throw Error("render: time budget must be finite and >= 0");
    if (!in_range(o.max_depth, 0, kMaxPathDepth))
        throw Error("render: max_depth must be in 0.." + std::to_string(kMaxPathDepth) + ", got " +
                    std::to_string(o.max_depth));
    if (!in_range(o.rr_depth, 0, kMaxPathDepth))
        throw Error("render: rr_depth must be in 0.." + std::to_string(kMaxPathDepth) + ", got " +
                    std::to_string(o.rr_depth));
    if (!in_range(o.reflection_depth, 0, kWhittedMaxDepth) || !in_range(o.refraction_depth, 0, kWhittedMaxDepth))
        throw Error("render: reflection and refraction depths must be in 0.." + std::to_string(kWhittedMaxDepth) +
                    ", got " + std::to_string(o.reflection_depth) + " and " + std::to_string(o.refraction_depth));
    if (!std::isfinite(o.max_sample_value) || o.max_sample_value < 0.0f)
        throw Error("render: max_sample_value must be finite and >= 0 (0 = no clamp)");
    if (!in_range(o.ao_samples, 1, kMaxAoSamples))
        throw Error("render: ao_samples must be in 1.." + std::to_string(kMaxAoSamples) + ", got " +
                    std::to_string(o.ao_samples));
    if (!std::isfinite(o.ao_radius) || o.ao_radius < 0.0f)
        throw Error("render: ao_radius must be finite and >= 0");
}

namespace {

// A film: per-pixel sums, added to in pass order.
std::vector<Vec3f> make_film(const RenderOptions& o, bool wanted) {
    return wanted ? std::vector<Vec3f>(size_t(o.width) * size_t(o.height), Vec3f(0.0f)) : std::vector<Vec3f>{};
}

Image mean_image(const std::vector<Vec3f>& sums, int width, int height, int passes) {
    if (sums.empty()) return {};
    Image image(width, height);
    const float scale = passes > 0 ? 1.0f / float(passes) : 0.0f;
    for (size_t i = 0; i < sums.size(); ++i) image.pixels[i] = sums[i] * scale;
    return image;
}

}  // namespace

struct ProgressiveRenderer::State {
    const Accel* accel;
    RenderOptions options;
    CameraFrame frame;
    HostSceneView view;
    AoSettings ao;
    WhittedSettings whitted;
    PathSettings path;
    std::vector<Vec3f> color, albedo, normal, depth;
    int passes = 0;
    RenderStats stats;
    Box3f sort_bounds;                // wavefront ray sorting: the scene and the camera
    WavefrontStats wavefront_stats;   // queue sizes of the wavefront passes

    State(const Scene& scene, const SceneGeometry& geometry, const Accel& accel_, const Camera& camera,
          const RenderOptions& o)
        : accel(&accel_),
          options(o),
          frame(CameraFrame::make(camera, o.width, o.height)),
          view(scene, geometry),
          color(make_film(o, true)),
          albedo(make_film(o, o.aovs)),
          normal(make_film(o, o.aovs)),
          depth(make_film(o, o.aovs)) {
        ao = {.samples = o.ao_samples, .radius = o.ao_radius > 0.0f ? o.ao_radius : 0.1f * view.diagonal()};
        whitted.reflection_depth = o.reflection_depth;
        whitted.refraction_depth = o.refraction_depth;
        whitted.shading = int(o.whitted_shading);
        path.max_depth = o.max_depth;
        path.rr_depth = o.rr_depth;
        path.strategy = int(o.light_sampling);
        path.pixel_spread = pixel_spread_angle(camera.vfov_degrees * (kPi / 180.0f), o.height);
        sort_bounds = geometry.bounds;
        sort_bounds.extend(frame.eye);
    }
};

ProgressiveRenderer::ProgressiveRenderer(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
                                         const Camera& camera, const RenderOptions& options) {
    validate_render_options(options);
    state_ = std::make_unique<State>(scene, geometry, accel, camera, options);
}

ProgressiveRenderer::~ProgressiveRenderer() = default;

void ProgressiveRenderer::render_pass(const ProgressCallback& progress) { run_pass(progress, nullptr); }

void ProgressiveRenderer::render_pass_recorded(std::vector<TracedRay>& rays) {
    std::vector<std::vector<TracedRay>> tile_logs;
    run_pass({}, &tile_logs);
    rays.clear();
    size_t total = 0;
    for (const auto& log : tile_logs) total += log.size();
    rays.reserve(total);
    for (const auto& log : tile_logs) rays.insert(rays.end(), log.begin(), log.end());
}

void ProgressiveRenderer::run_pass(const ProgressCallback& progress, std::vector<std::vector<TracedRay>>* tile_logs) {
    State& st = *state_;
    const RenderOptions& o = st.options;
    // A recorded pass is traced path by path, so its log keeps tile order
    // (the wavefront renders the same image).
    if (o.integrator == IntegratorKind::Path && o.wavefront && !tile_logs) {
        const Clock::time_point start = Clock::now();
        WavefrontPass pass;
        pass.accel = st.accel;
        pass.view = &st.view;
        pass.camera = st.frame;
        pass.width = o.width;
        pass.height = o.height;
        pass.sample = uint32_t(st.passes);
        pass.seed = o.seed;
        pass.settings = st.path;
        pass.max_sample_value = o.max_sample_value;
        pass.sort_rays = o.sort_rays;
        pass.sort_bounds = st.sort_bounds;
        pass.progress = progress;
        WavefrontFilms films{st.color.data(), nullptr, nullptr, nullptr};
        if (o.aovs) films = {st.color.data(), st.albedo.data(), st.normal.data(), st.depth.data()};
        WavefrontStats stats;
        parallel::with_threads(o.threads, [&] { render_wavefront_pass(pass, films, stats); });
        ++st.passes;
        st.stats.samples += uint64_t(o.width) * uint64_t(o.height);
        st.stats.closest_rays += stats.closest_rays;
        st.stats.shadow_rays += stats.shadow_rays;
        st.stats.seconds += std::chrono::duration<double>(Clock::now() - start).count();
        st.wavefront_stats += stats;
        return;
    }
    const int width = o.width, height = o.height;
    const int tiles_x = (width + kTileSize - 1) / kTileSize;
    const int tiles_y = (height + kTileSize - 1) / kTileSize;
    const int tile_count = tiles_x * tiles_y;
    const uint32_t sample = uint32_t(st.passes);
    // One sample per pixel at the pixel centre keeps single-sample whitted and
    // normals images free of jitter; the path tracer always jitters.
    const bool centre = o.spp == 1 && o.integrator != IntegratorKind::Path;
    const float clamp = o.max_sample_value;
    int tiles_done = 0;
    std::mutex progress_mutex;
    std::atomic<uint64_t> closest_total{0}, shadow_total{0};
    if (tile_logs) tile_logs->assign(size_t(tile_count), {});
    const Clock::time_point start = Clock::now();

    auto render_tile = [&](int tile) {
        uint64_t closest = 0, shadow = 0;
        const AccelTracer tracer{st.accel, &closest, &shadow, tile_logs ? &(*tile_logs)[size_t(tile)] : nullptr};
        int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
        int x1 = std::min(x0 + kTileSize, width), y1 = std::min(y0 + kTileSize, height);
        for (int y = y0; y < y1; ++y) {
            for (int x = x0; x < x1; ++x) {
                const size_t pixel = size_t(y) * size_t(width) + size_t(x);
                RandomStream rng(uint32_t(pixel), sample, o.seed);
                Vec2f jitter = centre ? Vec2f{0.5f, 0.5f} : rng.next2();
                Vec2f lens = rng.next2();
                Ray ray = st.frame.generate(float(x) + jitter.x, float(y) + jitter.y, width, height, lens.x, lens.y);
                FirstHitAovs aovs;
                Vec3f value;
                switch (o.integrator) {
                    case IntegratorKind::Normals: value = normals_radiance(tracer, st.view, ray); break;
                    case IntegratorKind::AmbientOcclusion: value = ao_radiance(tracer, st.view, ray, rng, st.ao); break;
                    case IntegratorKind::Path:
                        value = path_radiance(tracer, st.view, ray, rng, st.path, o.aovs ? &aovs : nullptr);
                        break;
                    case IntegratorKind::Whitted:
                    default: value = whitted_radiance(tracer, st.view, ray, rng, st.whitted); break;
                }
                // A NaN or infinity from a degenerate triangle must not
                // poison the pixel; such samples count as black.
                if (!is_finite(value)) value = Vec3f(0.0f);
                if (clamp > 0.0f && max_component(value) > clamp) value = value * (clamp / max_component(value));
                st.color[pixel] += value;
                if (o.aovs) {
                    if (o.integrator != IntegratorKind::Path) aovs = first_hit_aovs(tracer, st.view, ray);
                    st.albedo[pixel] += aovs.albedo;
                    st.normal[pixel] += aovs.normal;
                    st.depth[pixel] += Vec3f(aovs.depth);
                }
            }
        }
        closest_total += closest;
        shadow_total += shadow;
        if (progress) {
            // Counting under the lock keeps the reported fractions increasing.
            std::lock_guard<std::mutex> lock(progress_mutex);
            progress(double(++tiles_done) / double(tile_count));
        }
    };

    parallel::with_threads(o.threads, [&] { parallel::for_each_index(0, tile_count, render_tile); });
    ++st.passes;
    st.stats.samples += uint64_t(width) * uint64_t(height);
    st.stats.closest_rays += closest_total.load();
    st.stats.shadow_rays += shadow_total.load();
    st.stats.seconds += std::chrono::duration<double>(Clock::now() - start).count();
}

int ProgressiveRenderer::passes() const { return state_->passes; }
const RenderOptions& ProgressiveRenderer::options() const { return state_->options; }
RenderStats ProgressiveRenderer::stats() const { return state_->stats; }

Image ProgressiveRenderer::image() const {
    return mean_image(state_->color, state_->options.width, state_->options.height, state_->passes);
}
Image ProgressiveRenderer::albedo() const {
    return mean_image(state_->albedo, state_->options.width, state_->options.height, state_->passes);
}
Image ProgressiveRenderer::normal() const {
    return mean_image(state_->normal, state_->options.width, state_->options.height, state_->passes);
}
Image ProgressiveRenderer::depth() const {
    return mean_image(state_->depth, state_->options.width, state_->options.height, state_->passes);
}

void render_progressive(ProgressiveRenderer& renderer, const PassCallback& after_pass,
                        const ProgressCallback& progress) {
    const RenderOptions& o = renderer.options();
    const Clock::time_point start = Clock::now();
    const double budget = o.time_budget_s;
    double reported = 0.0;
    auto elapsed = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
    while (renderer.passes() < o.spp) {
        const int pass = renderer.passes();
        ProgressCallback pass_progress;
        if (progress) {
            pass_progress = [&](double fraction) {
                double done = (double(pass) + fraction) / double(o.spp);
                if (budget > 0.0) done = std::max(done, std::min(1.0, elapsed() / budget));
                done = std::min(done, 1.0);
                if (done <= reported) return;  // keep the reported fractions increasing
                reported = done;
                progress(done);
            };
        }
        renderer.render_pass(pass_progress);
        if (after_pass && !after_pass(renderer)) break;
        if (budget > 0.0 && elapsed() >= budget) break;
    }
    if (progress && reported < 1.0) progress(1.0);  // stopped early by the budget or the callback
}

Image render(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, const Camera& camera,
             const RenderOptions& options, const ProgressCallback& progress) {
    ProgressiveRenderer renderer(scene, geometry, accel, camera, options);
    render_progressive(renderer, {}, progress);
    return renderer.image();
}

IntegratorKind parse_integrator(const std::string& name) {
    if (name == "normals") return IntegratorKind::Normals;
    if (name == "ao") return IntegratorKind::AmbientOcclusion;
    if (name == "whitted") return IntegratorKind::Whitted;
    if (name == "path") return IntegratorKind::Path;
    throw Error("unknown integrator '" + name + "' (expected normals, ao, whitted or path)");
}

std::string integrator_name(IntegratorKind kind) {
    switch (kind) {
        case IntegratorKind::Normals: return "normals";
        case IntegratorKind::AmbientOcclusion: return "ao";
        case IntegratorKind::Whitted: return "whitted";
        case IntegratorKind::Path: return "path";
    }
    return "unknown";
}

LightSampling parse_light_sampling(const std::string& name) {
    if (name == "mis") return LightSampling::Mis;
    if (name == "nee") return LightSampling::Nee;
    if (name == "bsdf") return LightSampling::Bsdf;
    throw Error("unknown light sampling '" + name + "' (expected mis, nee or bsdf)");
}

std::string to_string(LightSampling sampling) {
    switch (sampling) {
        case LightSampling::Mis: return "mis";
        case LightSampling::Nee: return "nee";
        case LightSampling::Bsdf: return "bsdf";
    }
    return "unknown";
}

WhittedShading parse_whitted_shading(const std::string& name) {
    if (name == "lambert") return WhittedShading::Lambert;
    if (name == "phong") return WhittedShading::Phong;
    if (name == "blinn") return WhittedShading::Blinn;
    throw Error("unknown whitted shading '" + name + "' (expected lambert, phong or blinn)");
}

std::string to_string(WhittedShading shading) {
    switch (shading) {
        case WhittedShading::Lambert: return "lambert";
        case WhittedShading::Phong: return "phong";
        case WhittedShading::Blinn: return "blinn";
    }
    return "unknown";
}

}  // namespace rf
