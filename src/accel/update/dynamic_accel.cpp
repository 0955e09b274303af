// build_dynamic_accel: an rf::Accel kept current over an animation.
//
// The triangle-BVH methods (refit, adapt, rebuild, clusters: one file each
// in this folder) keep a canonical BVH current (accel/update/bvh_updater.h)
// and this file keeps
// the traversal layout current over it: when an update kept the topology
// (refit; adapt and clusters frames where nothing was restructured) the
// layout is refitted in place (BVH8/BVH4: accel/bvh/refit.h's
// refit_wide_bvh rewrites the triangle packs and child boxes; BVH2: the
// node boxes are copied), otherwise it is collapsed again from the new
// tree. The two-level method is its own accel (two_level_accel.cpp).
//
// On a CUDA device the backend makes the structure
// (backend/cuda/device_dynamic_accel.cpp): refit, rebuild and two-level.
#include <algorithm>
#include <chrono>
#include <functional>
#include <utility>

#include "accel/accel_factories.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/bvh_accel.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel/bvh/refit.h"
#include "accel/update/bvh_updater.h"
#include "accel/view_accel.h"
#include "backend/backends.h"
#include "core/parallel.h"
#include "backend/cpu/wide_bvh_tracer.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

// The traversal layout over a canonical tree, and how to refit it in place.
struct TracedLayout {
    std::unique_ptr<Accel> accel;
    std::function<void(const Bvh&, std::span<const Triangle>)> refit;
    std::function<void(AccelStats)> rename;
};

template <int N>
TracedLayout wide_layout(const SceneGeometry& geometry, const Bvh& bvh, AccelStats stats) {
    using WideAccel = ViewAccel<WideBvh<N>, WideBvhTracer<N>>;
    const auto make_tracer = [](const WideBvh<N>& w) {
        return WideBvhTracer<N>{
            WideBvhView<N>{w.nodes.data(), w.packs.data(), static_cast<uint32_t>(w.nodes.size()), w.coord_scale}};
    };
    auto accel = std::make_unique<WideAccel>(collapse_bvh<N>(bvh, geometry.triangles), make_tracer, std::move(stats));
    WideAccel* raw = accel.get();
    auto refit = [raw, make_tracer](const Bvh&, std::span<const Triangle> triangles) {
        raw->update_in_place([&](WideBvh<N>& wide) { refit_wide_bvh<N>(wide, triangles); }, make_tracer,
                             raw->stats());
    };
    auto rename = [raw, make_tracer](AccelStats s) {
        raw->update_in_place([](WideBvh<N>&) {}, make_tracer, std::move(s));
    };
    return {std::move(accel), std::move(refit), std::move(rename)};
}

TracedLayout binary_layout(const SceneGeometry& geometry, const Bvh& bvh, AccelStats stats) {
    auto accel = std::make_unique<BvhAccel>(geometry, bvh, stats.name, stats.build_ms);
    BvhAccel* raw = accel.get();
    const BvhView view = raw->view();
    const auto make_tracer = [view](const Bvh&) { return Bvh2Tracer{view}; };
    auto refit = [raw, make_tracer](const Bvh& source, std::span<const Triangle>) {
        raw->update_in_place(
            [&](Bvh& traced) {
                RF_ASSERT(traced.nodes.size() == source.nodes.size(), "a refit changed the node count");
                std::copy(source.nodes.begin(), source.nodes.end(), traced.nodes.begin());
            },
            make_tracer, raw->stats());
    };
    auto rename = [raw, make_tracer](AccelStats s) { raw->update_in_place([](Bvh&) {}, make_tracer, std::move(s)); };
    return {std::move(accel), std::move(refit), std::move(rename)};
}

TracedLayout make_layout(const SceneGeometry& geometry, const Bvh& bvh, Layout layout, AccelStats stats) {
    switch (layout) {
        case Layout::Bvh2: return binary_layout(geometry, bvh, std::move(stats));
        case Layout::Bvh4: return wide_layout<4>(geometry, bvh, std::move(stats));
        case Layout::Bvh8: return wide_layout<8>(geometry, bvh, std::move(stats));
    }
    throw Error("dynamic accel: unknown layout");
}

class DynamicBvhAccel final : public DynamicAccel {
public:
    DynamicBvhAccel(const Scene& scene, const SceneGeometry& geometry, const BuildOptions& build,
                    const UpdateOptions& update)
        : geometry_(geometry), build_(build), method_(update.method.value_or(kDefaultUpdateMethod)) {
        const auto start = std::chrono::steady_clock::now();
        parallel::with_threads(build.threads, [&] { updater_ = make_updater(scene, update); });
        initial_build_ms_ = ms_since(start);
        layout_ = make_layout(geometry_, updater_->bvh(), build_.layout, stats_named(initial_build_ms_, 0.0));
    }

    UpdateStats update(const GeometryChange& change) override {
        UpdateStats stats;
        stats.sah_cost = updater_->bvh().sah_cost(build_.sah.traversal, build_.sah.intersection);
        if (!change.geometry()) return stats;  // nothing moved: nothing to do
        const auto start = std::chrono::steady_clock::now();
        bool topology_changed = false;
        parallel::with_threads(build_.threads, [&] {
            topology_changed = updater_->update(geometry_.triangles, stats);
            const auto layout_start = std::chrono::steady_clock::now();
            if (topology_changed) {
                layout_ = make_layout(geometry_, updater_->bvh(), build_.layout, stats_named(0.0, 0.0));
            } else {
                layout_.refit(updater_->bvh(), geometry_.triangles);
            }
            stats.layout_ms = ms_since(layout_start);
        });
        stats.update_ms = ms_since(start);
        stats.sah_cost = updater_->bvh().sah_cost(build_.sah.traversal, build_.sah.intersection);
        rename_layout(stats);
        return stats;
    }

    [[nodiscard]] UpdateMethod method() const override { return method_; }
    [[nodiscard]] double initial_build_ms() const override { return initial_build_ms_; }

    [[nodiscard]] Hit intersect(const Ray& ray) const override { return layout_.accel->intersect(ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return layout_.accel->occluded(ray); }
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override {
        layout_.accel->intersect(rays, hits);
    }
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        layout_.accel->occluded(rays, occluded);
    }
    [[nodiscard]] AccelStats stats() const override {
        AccelStats s = layout_.accel->stats();
        s.sah_cost = updater_->bvh().sah_cost(build_.sah.traversal, build_.sah.intersection);
        s.quality_cost = updater_->bvh().quality_cost(2.0);
        return s;
    }
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override {
        return layout_.accel->count_traversal(rays, any_hit, totals);
    }
    std::vector<double> time_traversal(std::span<const Ray> rays, bool any_hit, int runs, std::span<Hit> hits,
                                       std::span<uint8_t> occluded) const override {
        return layout_.accel->time_traversal(rays, any_hit, runs, hits, occluded);
    }

private:
    std::unique_ptr<BvhUpdater> make_updater(const Scene& scene, const UpdateOptions& update) {
        const std::span<const Triangle> triangles = geometry_.triangles;
        switch (method_) {
            case UpdateMethod::Refit: return make_refit_updater(triangles, build_);
            case UpdateMethod::Rebuild: return make_rebuild_updater(triangles, build_);
            case UpdateMethod::Adapt: return make_adapt_updater(triangles, build_, update.adapt);
            case UpdateMethod::Clusters: return make_cluster_updater(scene, geometry_, build_, update.clusters);
            case UpdateMethod::TwoLevel: break;
        }
        throw Error("dynamic accel: " + to_string(method_) + " is not a triangle-BVH method");
    }

    [[nodiscard]] AccelStats stats_named(double build_ms, double layout_ms) const {
        AccelStats s;
        s.name = to_string(method_) + "/" + to_string(build_.builder) + "/" + to_string(build_.layout);
        s.build_ms = build_ms;
        s.layout_ms = layout_ms;
        return s;
    }
    // The layout's stats carry the last update's times under this accel's name.
    void rename_layout(const UpdateStats& stats) {
        layout_.rename(stats_named(stats.update_ms, stats.layout_ms));
    }

    const SceneGeometry& geometry_;
    BuildOptions build_;
    UpdateMethod method_;
    std::unique_ptr<BvhUpdater> updater_;
    TracedLayout layout_;
    double initial_build_ms_ = 0.0;
};

}  // namespace

std::unique_ptr<DynamicAccel> build_dynamic_accel(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build, const UpdateOptions& update,
                                                  const ProgressCallback& progress) {
    validate_build_options(build);
    validate_update_options(update);
    if (build.structure != Structure::Bvh)
        throw Error("dynamic accel: --update needs the bvh structure, not " + to_string(build.structure));
    if (progress) progress(0.0);
    std::unique_ptr<DynamicAccel> accel;
    if (build.device.is_cuda()) {
        accel = cuda::build_dynamic_accel(scene, geometry, build, update);
    } else if (update.method.value_or(kDefaultUpdateMethod) == UpdateMethod::TwoLevel) {
        accel = make_two_level_accel(scene, geometry, build);
    } else {
        accel = std::make_unique<DynamicBvhAccel>(scene, geometry, build, update);
    }
    if (progress) progress(1.0);
    return accel;
}

}  // namespace rf
