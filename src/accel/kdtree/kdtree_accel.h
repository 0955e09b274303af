// rf::Accel over the SAH kd-tree of seed 002 (kdtree_build.h), traced with
// one of the four traversals of trace/kdtree_traversal.h.
#pragma once

#include <string>
#include <utility>

#include "accel/kdtree/kdtree.h"
#include "rayforge/accel/accel.h"
#include "trace/kdtree_traversal.h"

namespace rf {

class KdTreeAccel final : public Accel {
public:
    // Traces `tree`, built over `geometry` in `build_ms`, with `traversal`;
    // `geometry` must outlive this object.
    KdTreeAccel(const SceneGeometry& geometry, KdTree tree, KdTraversal traversal, int short_stack_size,
                double build_ms)
        : geometry_(geometry), tree_(std::move(tree)), traversal_(traversal), short_stack_size_(short_stack_size),
          build_ms_(build_ms) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override;
    [[nodiscard]] bool occluded(const Ray& ray) const override;
    // Batches call the traversal directly (no virtual call per ray).
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override;
    [[nodiscard]] AccelStats stats() const override;
    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override;

    [[nodiscard]] const KdTree& tree() const { return tree_; }
    [[nodiscard]] KdTraversal traversal() const { return traversal_; }
    [[nodiscard]] KdTreeView view() const {
        return {tree_.nodes.data(), tree_.prim_indices.data(), geometry_.triangles.data(),
                static_cast<uint32_t>(tree_.nodes.size()), tree_.bounds, short_stack_size_};
    }

private:
    const SceneGeometry& geometry_;
    KdTree tree_;
    KdTraversal traversal_;
    int short_stack_size_;
    double build_ms_ = 0.0;
};

}  // namespace rf
