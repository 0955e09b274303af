// The CPU's rf::Accel over any structure: one adapter for every structure
// and layout. A Structure owns the arrays (Bvh, KdTree, UniformGrid,
// WideBvh<N>, or nothing for brute force); a Tracer (trace/tracers.h,
// backend/cpu/wide_bvh_tracer.h) answers queries on a view of them. The
// tracer structs are the ones the CUDA kernels run, so a structure is traced
// by the same code on both backends.
//
// Batches run the tracer over rays in parallel (TBB tasks of kRayGrainSize
// rays), or its own batch loop when it has one (packets); the instrumented
// pass sums its counted traversal, when it has one.
#pragma once

#include <span>
#include <string>
#include <utility>

#include "backend/cpu/ray_batches.h"
#include "core/assert.h"
#include "rayforge/accel/accel.h"
#include "trace/tracers.h"

namespace rf {

// What a structure adds to its AccelStats when asked (defined per structure).
struct NoStructure {};
inline void describe_structure(const NoStructure&, AccelStats&) {}

template <class Structure, class Tracer>
class ViewAccel : public Accel {
public:
    // Moves `structure` in, then makes the tracer over the moved arrays:
    // make_tracer(const Structure&) -> Tracer. `stats` holds the name and the
    // build and layout times; the rest is filled from the structure on request.
    template <class MakeTracer>
    ViewAccel(Structure structure, MakeTracer&& make_tracer, AccelStats stats)
        : structure_(std::move(structure)), tracer_(make_tracer(structure_)), stats_(std::move(stats)) {
        RF_ASSERT(!stats_.name.empty(), "an accel without a name for its stats and errors");
    }

    [[nodiscard]] Hit intersect(const Ray& ray) const override { return tracer_.intersect(ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return tracer_.occluded(ray); }

    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override {
        check_batch_sizes(stats_.name, rays.size(), hits.size());
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            if constexpr (requires { tracer_.intersect_batch(rays.data(), hits.data(), lo, hi); }) {
                tracer_.intersect_batch(rays.data(), hits.data(), lo, hi);
            } else {
                for (size_t i = lo; i != hi; ++i) hits[i] = tracer_.intersect(rays[i]);
            }
        });
    }

    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        check_batch_sizes(stats_.name, rays.size(), occluded.size());
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            if constexpr (requires { tracer_.occluded_batch(rays.data(), occluded.data(), lo, hi); }) {
                tracer_.occluded_batch(rays.data(), occluded.data(), lo, hi);
            } else {
                for (size_t i = lo; i != hi; ++i) occluded[i] = tracer_.occluded(rays[i]) ? 1 : 0;
            }
        });
    }

    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override {
        if constexpr (requires(RayCounters c) { tracer_.counted(Ray{}, any_hit, c); }) {
            totals += sum_traversal_counts(rays, [&](const Ray& ray, TraversalTotals& acc) {
                RayCounters c;
                (void)tracer_.counted(ray, any_hit, c);
                acc.steps += c.steps;
                acc.prim_tests += c.prim_tests;
                acc.restarts += c.restarts;
                acc.node_fetches += c.node_fetches;
            });
            return true;
        } else {
            return false;
        }
    }

    [[nodiscard]] AccelStats stats() const override {
        AccelStats s = stats_;
        describe_structure(structure_, s);
        return s;
    }

    [[nodiscard]] const Structure& structure() const { return structure_; }
    [[nodiscard]] const Tracer& tracer() const { return tracer_; }
    // For updates that keep every array's size (refits): `update` changes
    // the structure, the tracer is made again over it (its views may copy
    // values such as a coordinate scale), `stats` replaces the name and times.
    template <class Update, class MakeTracer>
    void update_in_place(Update&& update, MakeTracer&& make_tracer, AccelStats stats) {
        update(structure_);
        tracer_ = make_tracer(structure_);
        stats_ = std::move(stats);
    }

private:
    Structure structure_;
    Tracer tracer_;
    AccelStats stats_;
};

}  // namespace rf
