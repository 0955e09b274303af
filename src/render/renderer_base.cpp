#include "render/renderer_base.h"

#include <chrono>

#include "rayforge/core/error.h"

namespace rf {

using Clock = std::chrono::steady_clock;

RendererBase::RendererBase(std::shared_ptr<WorldCore> world, const Camera& camera, const RenderOptions& options)
    : world_(std::move(world)), camera_(camera), options_(options) {
    validate_render_options(options);
}

void RendererBase::start() {
    const WorldCore::FrameReading frame(*world_);
    follow(frame);
}

void RendererBase::follow(const WorldCore::FrameReading& frame) {
    if (frame.version() == version_) return;
    scene_ = &frame.scene();
    geometry_ = &frame.geometry();
    accel_ = &frame.accel();
    version_ = frame.version();
    bounds_ = geometry_->bounds;
    structure_changed();
    tables_ = std::make_unique<SceneTables>(*scene_, *geometry_);
    tables_changed();
    settings_ = make_integrator_settings(options_, camera_, tables_->view(), bounds_);
    reset_films();
    restart();
}

void RendererBase::restart() {
    passes_ = 0;
    stats_ = {};
    last_ = {};
}

bool RendererBase::render_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel) {
    const WorldCore::FrameReading frame(*world_);
    follow(frame);
    // The callback may run on the pass's worker threads: there it works for
    // this reading (a query takes no lock; a change is an error, not a wait
    // for this very pass).
    ProgressCallback on_behalf;
    if (progress)
        on_behalf = [&](double fraction) {
            const WorldCore::OnBehalfOfReading mark(*world_);
            progress(fraction);
        };
    const Clock::time_point start = Clock::now();
    PassStats pass;
    if (!run_pass(on_behalf, nullptr, cancel, pass)) {
        reset_films();  // part of a pass was added: start over, as set_camera does
        restart();
        return false;
    }
    pass.pass_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    finish_pass(pass);
    return true;
}

void RendererBase::run_recorded_pass(std::vector<TracedRay>& log) {
    const WorldCore::FrameReading frame(*world_);
    follow(frame);
    const Clock::time_point start = Clock::now();
    PassStats pass;
    run_pass({}, &log, nullptr, pass);
    pass.pass_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    finish_pass(pass);
}

void RendererBase::render_pass_recorded(std::vector<TracedRay>&) {
    throw Error("render_pass_recorded: the renderer on " + to_string(device()) + " does not record its rays");
}

void RendererBase::finish_pass(PassStats& pass) {
    ++passes_;
    stats_.samples += uint64_t(options_.width) * uint64_t(options_.height);
    stats_.closest_rays += pass.closest_rays;
    stats_.shadow_rays += pass.shadow_rays;
    stats_.seconds += pass.pass_ms * 1e-3;
    last_ = std::move(pass);
}

Image RendererBase::film_mean(Film film) const {
    Image image = film_sums(film);
    const float scale = passes() > 0 ? 1.0f / float(passes()) : 0.0f;
    for (Vec3f& p : image.pixels) p = p * scale;
    return image;
}

// The tables are the renderer's own and the bounds those of the frame last
// followed, so neither needs the world; a newer frame redoes the settings at
// the next pass.
void RendererBase::set_camera(const Camera& camera) {
    camera_ = camera;
    settings_ = make_integrator_settings(options_, camera_, tables_->view(), bounds_);
    reset_films();
    restart();
}

void RendererBase::set_options(const RenderOptions& options) {
    validate_render_options(options);
    options_ = options;
    settings_ = make_integrator_settings(options_, camera_, tables_->view(), bounds_);
    reset_films();
    restart();
}

}  // namespace rf
