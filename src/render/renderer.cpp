// The public face of rendering (rayforge/render/render.h, rayforge/world.h):
// make_renderer (the backend chosen by the world: paged, or in core on its
// device), the progressive loop and the one-shot render, the same for every
// backend. (The options' checks and names: render_options.cpp.)

#include <algorithm>
#include <chrono>

#include "rayforge/core/error.h"
#include "backend/backends.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"
#include "world/world_core.h"

namespace rf {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

std::unique_ptr<Renderer> make_renderer(World& world, const Camera& camera, const RenderOptions& options) {
    std::shared_ptr<WorldCore> core = core_of(world);
    core->commit({});
    if (core->paged) return cpu::make_paged_renderer(std::move(core), camera, options);
    if (core->device.is_cuda()) return cuda::make_renderer(std::move(core), camera, options);
    return cpu::make_renderer(std::move(core), camera, options);
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

Image render(World& world, const Camera& camera, const RenderOptions& options, const ProgressCallback& progress) {
    const std::unique_ptr<Renderer> renderer = make_renderer(world, camera, options);
    render_progressive(*renderer, {}, progress);
    return renderer->image();
}

}  // namespace rf
