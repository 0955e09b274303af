// The kd-tree's rf::Accel: build timing and the traversal chosen by
// options.kdtree.traversal, as a compile-time parameter of the tracer.
#include "accel/kdtree/kdtree_accel.h"

#include <chrono>
#include <limits>
#include <type_traits>

#include "accel/accel_factories.h"
#include "accel/kdtree/kdtree_build.h"
#include "core/parallel.h"

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

void describe_structure(const KdTree& tree, AccelStats& s) {
    s.node_count = tree.nodes.size();
    s.leaf_count = tree.leaf_count();
    s.bytes = tree.memory_bytes();
    s.sah_cost = tree.sah_cost(1.0f, 1.0f);
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
}

std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry& geometry, KdTree tree, KdTraversal traversal,
                                         int short_stack_size, double build_ms) {
    AccelStats stats;
    stats.name = "kdtree/sah/" + to_string(traversal);
    stats.build_ms = build_ms;
    return with_traversal(traversal, [&](auto mode) -> std::unique_ptr<Accel> {
        constexpr KdTraversal kMode = decltype(mode)::value;
        const auto make_tracer = [&](const KdTree& t) {
            return KdTracer<kMode>{KdTreeView{t.nodes.data(), t.prim_indices.data(), geometry.triangles.data(),
                                              static_cast<uint32_t>(t.nodes.size()), t.bounds, short_stack_size}};
        };
        return std::make_unique<KdTreeAccel<kMode>>(std::move(tree), make_tracer, std::move(stats));
    });
}

std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry& geometry, const BuildOptions& options) {
    const auto start = std::chrono::steady_clock::now();
    KdTree tree = parallel::with_threads(options.threads, [&] {
        return build_kdtree(geometry.triangles, options.sah, options.binned, options.kdtree);
    });
    const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return make_kdtree_accel(geometry, std::move(tree), options.kdtree.traversal, options.kdtree.short_stack_size,
                             build_ms);
}

}  // namespace rf
