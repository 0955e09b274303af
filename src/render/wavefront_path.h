// Wavefront path tracing on the CPU (Laine, Karras and Aila 2013,
// "Megakernels Considered Harmful: Wavefront Path Tracing on GPUs"): one pass
// of the path tracer run stage by stage over queues of paths instead of path
// by path. All paths of a chunk are generated, then, while any is active:
// (optionally) the active queue is sorted by ray key (Garanzha and Loop 2010,
// ray_sort_key.h), every active ray is extended (one batch query to the
// Accel, then per ray past cut-outs), every hit is shaded (producing a queue
// of shadow connections), every shadow ray is tested (one batch query, or per
// ray through transparent surfaces), and the active queue is compacted. The
// stages are those of path_stages.h, the ones the megakernel path_radiance
// runs, and each path sees the same numbers in the same order, so the image
// is the megakernel's to the bit, whatever the sorting or the thread count.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/math/box.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/camera.h"
#include "render/integrators/path_stages.h"
#include "render/scene_view.h"

namespace rf {

// Paths in flight at once: bounds the queues' memory (about 200 bytes a path).
inline constexpr uint32_t kWavefrontChunkPaths = 1u << 16;

// The queues of one extension round (a bounce, or a pass through a blended surface).
struct WavefrontWave {
    uint64_t paths = 0;        // active paths extended
    uint64_t shadow_rays = 0;  // shadow connections made by shading them
};

// Queue sizes and query counts, summed over chunks and passes.
struct WavefrontStats {
    std::vector<WavefrontWave> waves;  // index: extension round, 0 = camera rays
    uint64_t closest_rays = 0;         // closest-hit queries, cut-out walks included
    uint64_t shadow_rays = 0;          // any-hit queries
    double sort_seconds = 0.0;         // computing keys and sorting the active queue

    WavefrontStats& operator+=(const WavefrontStats& o);
};

// Per-pixel sums one pass adds to; the AOV films are null when not wanted.
struct WavefrontFilms {
    Vec3f* color = nullptr;
    Vec3f* albedo = nullptr;
    Vec3f* normal = nullptr;
    Vec3f* depth = nullptr;
};

struct WavefrontPass {
    const Accel* accel = nullptr;
    const HostSceneView* view = nullptr;
    CameraFrame camera;
    int width = 0, height = 0;
    uint32_t sample = 0;  // the pass index
    uint32_t seed = 0;
    PathSettings settings;
    float max_sample_value = 0.0f;  // > 0: clamp each sample's radiance
    bool sort_rays = false;
    Box3f sort_bounds;              // the box ray origins are quantised in (scene and camera)
    ProgressCallback progress;      // fraction of the pass, after each chunk; may be empty
};

// Adds one sample per pixel to `films` (parallel over paths within each
// stage; call inside parallel::with_threads to bound the threads).
void render_wavefront_pass(const WavefrontPass& pass, const WavefrontFilms& films, WavefrontStats& stats);

// Stable sort of `queue` by `keys` (keys[i] belongs to queue[i]; both are
// permuted together): a least-significant-digit radix sort, 8 bits a round.
void sort_queue_by_key(std::span<uint32_t> queue, std::span<uint32_t> keys);

}  // namespace rf
