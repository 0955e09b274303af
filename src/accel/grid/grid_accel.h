// rf::Accel over a uniform grid, plain or with proximity clouds (seeds 001
// and 002), traversed by trace/grid_traversal.h.
#pragma once

#include <string>
#include <utility>

#include "accel/grid/uniform_grid.h"
#include "rayforge/accel/accel.h"
#include "trace/grid_traversal.h"

namespace rf {

class GridAccel final : public Accel {
public:
    // Traces `grid`, built over `geometry` in `build_ms`; `geometry` must outlive this object.
    GridAccel(const SceneGeometry& geometry, UniformGrid grid, std::string name, double build_ms)
        : geometry_(geometry), grid_(std::move(grid)), name_(std::move(name)), build_ms_(build_ms) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override { return grid_intersect(view(), ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return grid_occluded(view(), ray); }
    // Batches call the traversal directly (no virtual call per ray).
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override;
    [[nodiscard]] AccelStats stats() const override;
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override;

    [[nodiscard]] const UniformGrid& grid() const { return grid_; }
    [[nodiscard]] GridView view() const { return grid_.view(geometry_.triangles.data()); }

private:
    const SceneGeometry& geometry_;
    UniformGrid grid_;
    std::string name_;
    double build_ms_ = 0.0;
};

}  // namespace rf
