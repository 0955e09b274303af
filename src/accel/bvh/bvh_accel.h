// rf::Accel over the canonical BVH, traversed by trace/bvh_traversal.h.
#pragma once

#include <string>
#include <utility>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"
#include "trace/bvh_traversal.h"

namespace rf {

class BvhAccel final : public Accel {
public:
    // Traces `bvh`, built over `geometry` in `build_ms` by the builder `name`
    // describes (e.g. "bvh/binned/bvh2"); `geometry` must outlive this object.
    BvhAccel(const SceneGeometry& geometry, Bvh bvh, std::string name, double build_ms)
        : geometry_(geometry), bvh_(std::move(bvh)), name_(std::move(name)), build_ms_(build_ms) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override { return bvh_intersect(view(), ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return bvh_occluded(view(), ray); }
    // Batches call the traversal directly (no virtual call per ray).
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override;
    [[nodiscard]] AccelStats stats() const override;
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override;

    [[nodiscard]] const Bvh& bvh() const { return bvh_; }
    [[nodiscard]] BvhView view() const {
        return {bvh_.nodes.data(), bvh_.prim_indices.data(), geometry_.triangles.data(),
                static_cast<uint32_t>(bvh_.nodes.size())};
    }

private:
    const SceneGeometry& geometry_;
    Bvh bvh_;
    std::string name_;
    double build_ms_ = 0.0;
};

}  // namespace rf
