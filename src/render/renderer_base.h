// What every renderer shares (rf::Renderer): the world it draws and the
// frame of it the last pass saw, the options and camera with the integrator
// settings derived from them, the host shading tables, the pass count and
// statistics, and the restarts of set_camera and set_options. Each pass
// holds the world shared; when the world's frame changed since the last
// pass (World::set_time, an edit), the renderer binds to its structure
// again (structure_changed) and rebuilds its tables and films first. A
// backend supplies only its films, its pass and its display image:
// backend/cpu/cpu_renderer.cpp (tiles and the CPU wavefront),
// backend/cuda/renderer.cu (kernels) and ooc/paged_renderer.cpp.
#pragma once

#include <atomic>
#include <memory>
#include <vector>

#include "rayforge/render/render.h"
#include "render/integrator_settings.h"
#include "render/scene_view.h"
#include "world/world_core.h"

namespace rf {

class RendererBase : public Renderer {
public:
    bool render_pass(const ProgressCallback& progress, const std::atomic<bool>* cancel) final;
    void render_pass_recorded(std::vector<TracedRay>& rays) override;  // throws unless a backend records
    // A renderer whose world changed since its last pass has restarted: no
    // passes, no stats and a black image until its next pass follows the world.
    [[nodiscard]] int passes() const final { return behind_its_world() ? 0 : passes_; }
    [[nodiscard]] const RenderOptions& options() const final { return options_; }
    [[nodiscard]] Device device() const final { return world_->device; }
    [[nodiscard]] RenderStats stats() const final { return behind_its_world() ? RenderStats{} : stats_; }
    [[nodiscard]] const PassStats& last_pass() const final { return last_; }
    [[nodiscard]] Image image() const final { return film_mean(Film::Color); }
    [[nodiscard]] Image albedo() const final { return film_mean(Film::Albedo); }
    [[nodiscard]] Image normal() const final { return film_mean(Film::Normal); }
    [[nodiscard]] Image depth() const final { return film_mean(Film::Depth); }
    void set_camera(const Camera& camera) final;
    void set_options(const RenderOptions& options) final;

protected:
    enum class Film { Color, Albedo, Normal, Depth };

    // Validates `options`. A backend's constructor ends with start().
    RendererBase(std::shared_ptr<WorldCore> world, const Camera& camera, const RenderOptions& options);
    // Binds to the world's frame and builds the shading tables and the films.
    void start();

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
    // accel() is another structure (or the same one changed): a backend
    // that binds to it (the CUDA renderer's device tracer) does so again.
    virtual void structure_changed() {}

    void run_recorded_pass(std::vector<TracedRay>& log);

    [[nodiscard]] const SceneTables& tables() const { return *tables_; }
    [[nodiscard]] const IntegratorSettings& settings() const { return settings_; }
    [[nodiscard]] const SceneGeometry& geometry() const { return *geometry_; }
    [[nodiscard]] const Accel& accel() const { return *accel_; }
    [[nodiscard]] WorldCore& world() const { return *world_; }

private:
    [[nodiscard]] bool behind_its_world() const {
        return world_->version.load(std::memory_order_acquire) != version_;
    }
    [[nodiscard]] Image film_mean(Film film) const;
    // Brings the renderer to the frame `frame` holds when it is not there
    // yet: bound to its structure, tables, settings and films rebuilt.
    void follow(const WorldCore::FrameReading& frame);
    void restart();
    void finish_pass(PassStats& pass);

    std::shared_ptr<WorldCore> world_;
    const Scene* scene_ = nullptr;            // the frame of the world last followed
    const SceneGeometry* geometry_ = nullptr;
    const Accel* accel_ = nullptr;
    uint64_t version_ = 0;                     // 0: no frame followed yet
    Box3f bounds_;                             // of that frame's triangles
    Camera camera_;
    RenderOptions options_;
    std::unique_ptr<SceneTables> tables_;
    IntegratorSettings settings_;
    int passes_ = 0;
    RenderStats stats_;
    PassStats last_;
};

}  // namespace rf
