// Temporary weak definitions of the update methods still being written; each
// method's own file defines the strong symbol. (Removed once all have landed.)
#include "accel/dynamic/bvh_updater.h"
#include "rayforge/core/error.h"

namespace rf {

__attribute__((weak)) std::unique_ptr<BvhUpdater> make_refit_updater(std::span<const Triangle>, const BuildOptions&) {
    throw Error("update method refit is not available yet");
}
__attribute__((weak)) std::unique_ptr<BvhUpdater> make_adapt_updater(std::span<const Triangle>, const BuildOptions&,
                                                                     const AdaptOptions&) {
    throw Error("update method adapt is not available yet");
}
__attribute__((weak)) std::unique_ptr<BvhUpdater> make_cluster_updater(const Scene&, const SceneGeometry&,
                                                                       const BuildOptions&, const ClusterOptions&) {
    throw Error("update method clusters is not available yet");
}
__attribute__((weak)) std::unique_ptr<DynamicAccel> make_two_level_accel(const Scene&, const SceneGeometry&,
                                                                         const BuildOptions&) {
    throw Error("update method two-level is not available yet");
}

__attribute__((weak)) GeometryChange Scene::set_time(float) {
    throw Error("animation evaluation is not available yet");
}

}  // namespace rf
