// The public face of rendering (rayforge/render/render.h): make_renderer
// (the backend chosen by options.device), the progressive loop and the
// one-shot render, the same for every backend. (The options' checks and
// names: render_options.cpp.)

#include <algorithm>
#include <chrono>

#include "rayforge/core/error.h"
#include "backend/backends.h"
#include "rayforge/render/render.h"

namespace rf {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

std::unique_ptr<Renderer> make_renderer(const Scene& scene, const SceneGeometry& geometry, const Accel& accel,
                                        const Camera& camera, const RenderOptions& options) {
    if (options.device.is_cuda()) return cuda::make_renderer(scene, geometry, accel, camera, options);
    return cpu::make_renderer(scene, geometry, accel, camera, options);
}

void render_progressive(Renderer& renderer, const PassCallback& after_pass, const ProgressCallback& progress) {
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
        // A backend that reports no fraction within its pass still moves the bar.
        if (pass_progress) pass_progress(1.0);
        if (after_pass && !after_pass(renderer)) break;
        if (budget > 0.0 && elapsed() >= budget) break;
    }
    if (progress && reported < 1.0) progress(1.0);  // stopped early by the budget or the callback
}

Image render(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, const Camera& camera,
             const RenderOptions& options, const ProgressCallback& progress) {
    const std::unique_ptr<Renderer> renderer = make_renderer(scene, geometry, accel, camera, options);
    render_progressive(*renderer, {}, progress);
    return renderer->image();
}

}  // namespace rf
