// UpdateMethod::Rebuild: BuildOptions::builder from scratch every frame.
#include "accel/bvh/builders/build_bvh.h"
#include "accel/update/bvh_updater.h"

namespace rf {
namespace {

// Rebuild: the builder from scratch every frame.
class RebuildUpdater final : public BvhUpdater {
public:
    RebuildUpdater(std::span<const Triangle> triangles, const BuildOptions& build)
        : build_(build), bvh_(build_bvh_on_cpu(triangles, build)) {}
    [[nodiscard]] const Bvh& bvh() const override { return bvh_; }
    bool update(std::span<const Triangle> triangles, UpdateStats&) override {
        bvh_ = build_bvh_on_cpu(triangles, build_);
        return true;
    }

private:
    BuildOptions build_;
    Bvh bvh_;
};

}  // namespace

std::unique_ptr<BvhUpdater> make_rebuild_updater(std::span<const Triangle> triangles, const BuildOptions& build) {
    return std::make_unique<RebuildUpdater>(triangles, build);
}

}  // namespace rf
