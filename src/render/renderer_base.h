// What both backends' renderers share (rf::Renderer): the scene they draw,
// the options and camera with the integrator settings derived from them,
// the host shading tables, the pass count and statistics, and the restarts
// of set_camera, set_options and scene_changed. A backend supplies only its
// films, its pass and its display image: backend/cpu/cpu_renderer.cpp (tiles
// and the CPU wavefront) and backend/cuda/renderer.cu (kernels).
#pragma once

#include <atomic>
#include <memory>
#include <vector>

#include "rayforge/render/render.h"
#include "render/integrator_settings.h"
#include "render/scene_view.h"

namespace rf {

class RendererBase : public Renderer {
public:
    bool render_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel) final;
    void render_pass_recorded(std::vector<TracedRay>& rays) override;  // throws unless a backend records
    [[nodiscard]] int passes() const final { return passes_; }
    [[nodiscard]] const RenderOptions& options() const final { return options_; }
    [[nodiscard]] Device device() const final { return options_.device; }
    [[nodiscard]] RenderStats stats() const final { return stats_; }
    [[nodiscard]] const PassStats& last_pass() const final { return last_; }
    [[nodiscard]] Image image() const final { return film_mean(Film::Color); }
    [[nodiscard]] Image albedo() const final { return film_mean(Film::Albedo); }
    [[nodiscard]] Image normal() const final { return film_mean(Film::Normal); }
    [[nodiscard]] Image depth() const final { return film_mean(Film::Depth); }
    void set_camera(const Camera& camera) final;
    void set_options(const RenderOptions& options) final;
    void scene_changed(SceneChange what) final;

protected:
    enum class Film { Color, Albedo, Normal, Depth };

    // Validates `options`. A backend's constructor ends with reset(), which
    // builds the shading tables and the films.
    RendererBase(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, const Camera& camera,
                 const RenderOptions& options);

    // Adds one sample per pixel (sample index passes()) to the films,
    // filling `stats` (rays, waves); `log`, when given, gets every query.
    // Returns false when it saw `cancel` set and stopped early (the films
    // then hold part of a pass; render_pass restarts them).
    virtual bool run_pass(const ProgressCallback& progress, std::vector<TracedRay>* log,
                          const std::atomic<bool>* cancel, PassStats& stats) = 0;
    // The per-pixel sums of a film (an empty image when it is off).
    [[nodiscard]] virtual Image film_sums(Film film) const = 0;
    // Films sized for options() and zeroed.
    virtual void reset_films() = 0;
    // The shading tables were rebuilt: a backend that copies them does so again.
    virtual void tables_changed() {}

    // Rebuilds the shading tables (and calls tables_changed()), the films and
    // the settings; no passes and no stats after it.
    void reset();
    void run_recorded_pass(std::vector<TracedRay>& log);

    [[nodiscard]] const SceneTables& tables() const { return *tables_; }
    [[nodiscard]] const IntegratorSettings& settings() const { return settings_; }
    [[nodiscard]] const SceneGeometry& geometry() const { return geometry_; }
    [[nodiscard]] const Accel& accel() const { return accel_; }

private:
    [[nodiscard]] Image film_mean(Film film) const;
    void restart();
    void finish_pass(PassStats& pass);

    const Scene& scene_;
    const SceneGeometry& geometry_;
    const Accel& accel_;
    Camera camera_;
    RenderOptions options_;
    std::unique_ptr<SceneTables> tables_;
    IntegratorSettings settings_;
    int passes_ = 0;
    RenderStats stats_;
    PassStats last_;
};

}  // namespace rf
