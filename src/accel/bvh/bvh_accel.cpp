#include "backend/cpu/ray_batches.h"
#include "accel/bvh/bvh_accel.h"

#include "backend/cpu/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

AccelStats BvhAccel::stats() const {
    AccelStats s;
    s.name = name_;
    s.build_ms = build_ms_;
    s.node_count = bvh_.nodes.size();
    s.leaf_count = bvh_.leaf_count();
    s.bytes = bvh_.memory_bytes();
    s.sah_cost = bvh_.sah_cost(1.0f, 1.0f);
    s.quality_cost = bvh_.quality_cost(2.0);
    return s;
}

namespace {



}  // namespace

void BvhAccel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    check_batch_sizes("BvhAccel::intersect", rays.size(), hits.size());
    const BvhView bvh = view();
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) hits[i] = bvh_intersect(bvh, rays[i]);
    });
}

void BvhAccel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    check_batch_sizes("BvhAccel::occluded", rays.size(), occluded.size());
    const BvhView bvh = view();
    parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i != hi; ++i) occluded[i] = bvh_occluded(bvh, rays[i]) ? 1 : 0;
    });
}

bool BvhAccel::count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const {
    const BvhView bvh = view();
    totals += sum_traversal_counts(rays, [&](const Ray& ray, TraversalTotals& acc) {
        TraversalCounters counters;
        if (any_hit) (void)bvh_occluded_counted(bvh, ray, counters);
        else (void)bvh_intersect_counted(bvh, ray, counters);
        acc.steps += counters.nodes_visited;
        acc.prim_tests += counters.prims_tested;
    });
    return true;
}

}  // namespace rf
