// UpdateMethod::Refit: one build, then every frame a refit of the tree's
// boxes (accel/bvh/refit.h: Karras 2012's bottom-up pass over a kept
// topology; Garanzha 2014 ch. 2's first stage).
#include <string>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/refit.h"
#include "accel/update/bvh_updater.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

class RefitUpdater final : public BvhUpdater {
public:
    RefitUpdater(std::span<const Triangle> triangles, const BuildOptions& build)
        : threads_(build.threads), triangle_count_(triangles.size()) {
        bvh_ = build_bvh_on_cpu(triangles, build);
        plan_ = parallel::with_threads(threads_, [&] { return make_refit_plan(bvh_); });
    }

    [[nodiscard]] const Bvh& bvh() const override { return bvh_; }

    bool update(std::span<const Triangle> triangles, UpdateStats& stats) override {
        if (triangles.size() != triangle_count_) {
            throw Error("refit update: " + std::to_string(triangles.size()) + " triangles, the tree was built over " +
                        std::to_string(triangle_count_));
        }
        parallel::with_threads(threads_, [&] { refit_bvh(bvh_, triangles, plan_); });
        stats.refitted_nodes = bvh_.nodes.size();
        return false;  // only boxes changed
    }

private:
    int threads_;
    size_t triangle_count_;
    Bvh bvh_;
    RefitPlan plan_;
};

}  // namespace

std::unique_ptr<BvhUpdater> make_refit_updater(std::span<const Triangle> triangles, const BuildOptions& build) {
    return std::make_unique<RefitUpdater>(triangles, build);
}

}  // namespace rf
