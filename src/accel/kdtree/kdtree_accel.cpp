// The kd-tree's rf::Accel (seed 002): build timing, the traversal chosen by
// options.kdtree.traversal, batches and counted traversals.
#include "backend/cpu/ray_batches.h"
#include "accel/kdtree/kdtree_accel.h"

#include <chrono>
#include <limits>
#include <type_traits>

#include "accel/accel_factories.h"
#include "accel/kdtree/kdtree_build.h"
#include "backend/cpu/parallel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {


// Calls f with the traversal as a compile-time constant.
template <class F>
decltype(auto) with_traversal(KdTraversal traversal, F&& f) {
    switch (traversal) {
        case KdTraversal::ShortStack: return f(std::integral_constant<KdTraversal, KdTraversal::ShortStack>{});
        case KdTraversal::Restart: return f(std::integral_constant<KdTraversal, KdTraversal::Restart>{});
        case KdTraversal::Pushdown: return f(std::integral_constant<KdTraversal, KdTraversal::Pushdown>{});
        case KdTraversal::Stack: break;
    }
    return f(std::integral_constant<KdTraversal, KdTraversal::Stack>{});
}


}  // namespace

Hit KdTreeAccel::intersect(const Ray& ray) const {
    const KdTreeView tree = view();
    return with_traversal(traversal_, [&](auto mode) { return kdtree_intersect<decltype(mode)::value>(tree, ray); });
}

bool KdTreeAccel::occluded(const Ray& ray) const {
    const KdTreeView tree = view();
    return with_traversal(traversal_, [&](auto mode) { return kdtree_occluded<decltype(mode)::value>(tree, ray); });
}

void KdTreeAccel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    check_batch_sizes("KdTreeAccel::intersect", rays.size(), hits.size());
    const KdTreeView tree = view();
    with_traversal(traversal_, [&](auto mode) {
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            for (size_t i = lo; i != hi; ++i) hits[i] = kdtree_intersect<decltype(mode)::value>(tree, rays[i]);
        });
    });
}

void KdTreeAccel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    check_batch_sizes("KdTreeAccel::occluded", rays.size(), occluded.size());
    const KdTreeView tree = view();
    with_traversal(traversal_, [&](auto mode) {
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            for (size_t i = lo; i != hi; ++i) occluded[i] = kdtree_occluded<decltype(mode)::value>(tree, rays[i]) ? 1 : 0;
        });
    });
}

bool KdTreeAccel::count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const {
    const KdTreeView tree = view();
    totals += with_traversal(traversal_, [&](auto mode) {
        return sum_traversal_counts(rays, [&](const Ray& ray, TraversalTotals& acc) {
            KdTraversalCounters counters;
            if (any_hit) (void)kdtree_occluded_counted<decltype(mode)::value>(tree, ray, counters);
            else (void)kdtree_intersect_counted<decltype(mode)::value>(tree, ray, counters);
            acc.steps += counters.nodes_visited;
            acc.prim_tests += counters.prims_tested;
            acc.restarts += counters.restarts;
        });
    });
    return true;
}

AccelStats KdTreeAccel::stats() const {
    AccelStats s;
    s.name = "kdtree/sah/" + to_string(traversal_);
    s.build_ms = build_ms_;
    s.node_count = tree_.nodes.size();
    s.leaf_count = tree_.leaf_count();
    s.bytes = tree_.memory_bytes();
    s.sah_cost = tree_.sah_cost(1.0f, 1.0f);
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
    return s;
}

std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry& geometry, const BuildOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    KdTree tree = parallel::with_threads(options.threads, [&] {
        return build_kdtree(geometry.triangles, options.sah, options.binned, options.kdtree);
    });
    const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return std::make_unique<KdTreeAccel>(geometry, std::move(tree), options.kdtree.traversal,
                                         options.kdtree.short_stack_size, build_ms);
}

}  // namespace rf
