// rf::render: the image is cut into 16x16 tiles rendered in parallel by TBB;
// every sample draws its random numbers from its own counter-based stream
// (render/random.h), so the result does not depend on the thread count or
// on which thread renders which tile.

#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "core/parallel.h"
#include "rayforge/render/render.h"
#include "render/integrators/ao.h"
#include "render/integrators/normals.h"
#include "render/integrators/whitted.h"
#include "render/random.h"
#include "render/scene_view.h"

namespace rf {
namespace {

constexpr int kTileSize = 16;
constexpr int kMaxImageSide = 65536;
constexpr size_t kMaxImageBytes = size_t(4) << 30;  // the float RGB film
constexpr int kMaxSpp = 1 << 20;
constexpr int kMaxAoSamples = 1 << 16;

void validate(const RenderOptions& o) {
    auto in_range = [](int v, int lo, int hi) { return v >= lo && v <= hi; };
    if (!in_range(o.width, 1, kMaxImageSide) || !in_range(o.height, 1, kMaxImageSide))
        throw Error("render: image size " + std::to_string(o.width) + "x" + std::to_string(o.height) +
                    " is outside 1.." + std::to_string(kMaxImageSide));
    size_t bytes = size_t(o.width) * size_t(o.height) * sizeof(Vec3f);
    if (bytes > kMaxImageBytes)
        throw Error("render: a " + std::to_string(o.width) + "x" + std::to_string(o.height) + " image needs " +
                    std::to_string(bytes >> 20) + " MiB, more than the " +
                    std::to_string(kMaxImageBytes >> 20) + " MiB allowed");
    checked_array_bytes("render: " + std::to_string(o.width) + "x" + std::to_string(o.height) + " image",
                        size_t(o.width) * size_t(o.height), sizeof(Vec3f));
    if (!in_range(o.spp, 1, kMaxSpp))
        throw Error("render: spp must be in 1.." + std::to_string(kMaxSpp) + ", got " + std::to_string(o.spp));
    if (o.threads < 0) throw Error("render: threads must be >= 0, got " + std::to_string(o.threads));
    if (!in_range(o.max_depth, 0, kWhittedMaxDepth))
        throw Error("render: max_depth must be in 0.." + std::to_string(kWhittedMaxDepth) + ", got " +
                    std::to_string(o.max_depth));
    if (!in_range(o.ao_samples, 1, kMaxAoSamples))
        throw Error("render: ao_samples must be in 1.." + std::to_string(kMaxAoSamples) + ", got " +
                    std::to_string(o.ao_samples));
    if (!std::isfinite(o.ao_radius) || o.ao_radius < 0.0f)
        throw Error("render: ao_radius must be finite and >= 0");
}

}  // namespace

Image render(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, const Camera& camera,
             const RenderOptions& options, const ProgressCallback& progress) {
    validate(options);
    const int width = options.width, height = options.height;
    const CameraFrame frame = CameraFrame::make(camera, width, height);
    const HostSceneView view(scene, geometry);
    const AccelTracer tracer{&accel};

    const AoSettings ao{.samples = options.ao_samples,
                        .radius = options.ao_radius > 0.0f ? options.ao_radius : 0.1f * view.diagonal()};
    const WhittedSettings whitted{.max_depth = options.max_depth};

    auto radiance = [&](const Ray& ray, RandomStream& rng) -> Vec3f {
        switch (options.integrator) {
            case IntegratorKind::Normals: return normals_radiance(tracer, view, ray);
            case IntegratorKind::AmbientOcclusion: return ao_radiance(tracer, view, ray, rng, ao);
            case IntegratorKind::Whitted:
            default: return whitted_radiance(tracer, view, ray, rng, whitted);
        }
    };

    Image image(width, height);
    const int tiles_x = (width + kTileSize - 1) / kTileSize;
    const int tiles_y = (height + kTileSize - 1) / kTileSize;
    const int tile_count = tiles_x * tiles_y;
    int tiles_done = 0;
    std::mutex progress_mutex;
    const float inv_spp = 1.0f / float(options.spp);

    auto render_tile = [&](int tile) {
        int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
        int x1 = std::min(x0 + kTileSize, width), y1 = std::min(y0 + kTileSize, height);
        for (int y = y0; y < y1; ++y) {
            for (int x = x0; x < x1; ++x) {
                uint32_t pixel = uint32_t(size_t(y) * size_t(width) + size_t(x));
                Vec3f sum(0.0f);
                for (int s = 0; s < options.spp; ++s) {
                    RandomStream rng(pixel, uint32_t(s), options.seed);
                    Vec2f jitter = options.spp == 1 ? Vec2f{0.5f, 0.5f} : rng.next2();
                    Vec2f lens = rng.next2();
                    Ray ray = frame.generate(float(x) + jitter.x, float(y) + jitter.y, width, height, lens.x, lens.y);
                    Vec3f value = radiance(ray, rng);
                    // A NaN or infinity from a degenerate triangle must not
                    // poison the pixel; such samples count as black.
                    if (is_finite(value)) sum += value;
                }
                image.at(x, y) = sum * inv_spp;
            }
        }
        if (progress) {
            // Counting under the lock keeps the reported fractions increasing.
            std::lock_guard<std::mutex> lock(progress_mutex);
            progress(double(++tiles_done) / double(tile_count));
        }
    };

    parallel::with_threads(options.threads, [&] { parallel::for_each_index(0, tile_count, render_tile); });
    return image;
}

IntegratorKind parse_integrator(const std::string& name) {
    if (name == "normals") return IntegratorKind::Normals;
    if (name == "ao") return IntegratorKind::AmbientOcclusion;
    if (name == "whitted") return IntegratorKind::Whitted;
    throw Error("unknown integrator '" + name + "' (expected normals, ao or whitted)");
}

std::string integrator_name(IntegratorKind kind) {
    switch (kind) {
        case IntegratorKind::Normals: return "normals";
        case IntegratorKind::AmbientOcclusion: return "ao";
        case IntegratorKind::Whitted: return "whitted";
    }
    return "unknown";
}

}  // namespace rf
