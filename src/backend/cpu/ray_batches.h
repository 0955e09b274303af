// What every structure's batched queries share: the grain of the parallel
// loops over rays, the check that results have one slot per ray, and the
// parallel sum of per-ray traversal counts.
#pragma once

#include <cstddef>
#include <span>
#include <string>
#include <string_view>

#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/math/ray.h"

namespace rf {

inline constexpr size_t kRayGrainSize = 256;  // rays per parallel task

inline void check_batch_sizes(std::string_view what, size_t rays, size_t results) {
    if (rays != results) {
        throw Error(std::string(what) + ": " + std::to_string(rays) + " rays but " + std::to_string(results) +
                    " result slots");
    }
}

// Totals of count_ray(ray, totals) over `rays`, which traces one ray with a
// counting traversal and adds its steps, primitive tests (and restarts) to
// `totals`; the ray count is added here.
template <class CountRay>
TraversalTotals sum_traversal_counts(std::span<const Ray> rays, CountRay&& count_ray) {
    return parallel::reduce(
        size_t(0), rays.size(), kRayGrainSize, TraversalTotals{},
        [&](size_t lo, size_t hi, TraversalTotals acc) {
            for (size_t i = lo; i != hi; ++i) count_ray(rays[i], acc);
            acc.rays += hi - lo;
            return acc;
        },
        [](TraversalTotals a, const TraversalTotals& b) { return a += b; });
}

}  // namespace rf
