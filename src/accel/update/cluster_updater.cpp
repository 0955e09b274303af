// UpdateMethod::Clusters (Garanzha 2014 ch. 3): clusters of connected
// triangles computed once from the first frame, and every frame a build
// over the clusters' boxes turned into the canonical tree
// (accel/bvh/builders/clusters.h), optionally over per-cluster subtrees
// refitted each frame.
#include <optional>
#include <string>

#include "accel/bvh/builders/cluster_generation.h"
#include "accel/bvh/builders/clusters.h"
#include "accel/update/bvh_updater.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

class ClusterUpdater final : public BvhUpdater {
public:
    ClusterUpdater(const Scene& scene, const SceneGeometry& geometry, const BuildOptions& build,
                   const ClusterOptions& options)
        : box_options_(cluster_box_build_options(build)), leaf_(options.leaf_triangles),
          triangle_count_(geometry.size()) {
        validate_cluster_options(options);
        parallel::with_threads(build.threads, [&] {
            clusters_ = cluster_scene(scene, geometry, options);
            if (options.cluster_subtrees) {
                subtrees_ = build_cluster_subtrees(geometry.triangles, clusters_, build);
                leaf_ = build.max_leaf_size;
            }
            bvh_ = rebuild(geometry.triangles);
        });
    }

    [[nodiscard]] const Bvh& bvh() const override { return bvh_; }

    bool update(std::span<const Triangle> triangles, UpdateStats& /*stats*/) override {
        if (triangles.size() != triangle_count_) {
            throw Error("cluster update: " + std::to_string(triangles.size()) + " triangles, built over " +
                        std::to_string(triangle_count_));
        }
        parallel::with_threads(box_options_.threads, [&] {
            if (subtrees_) refit_cluster_subtrees(triangles, clusters_, *subtrees_);
            bvh_ = rebuild(triangles);
        });
        return true;  // rebuilt: a new topology every frame
    }

private:
    Bvh rebuild(std::span<const Triangle> triangles) const {
        return build_cluster_bvh(triangles, clusters_, box_options_, leaf_, subtrees_ ? &*subtrees_ : nullptr);
    }

    BuildOptions box_options_;
    int leaf_;
    size_t triangle_count_;
    ClusterPartition clusters_;
    std::optional<ClusterSubtrees> subtrees_;
    Bvh bvh_;
};

}  // namespace

std::unique_ptr<BvhUpdater> make_cluster_updater(const Scene& scene, const SceneGeometry& geometry,
                                                 const BuildOptions& build, const ClusterOptions& options) {
    return std::make_unique<ClusterUpdater>(scene, geometry, build, options);
}

}  // namespace rf
