// rf::Accel over the 4- and 8-wide BVH layouts (accel/bvh/layout/wide_bvh.h),
// collapsed from the canonical binary BVH (Wald, Benthin and Boulos 2008).
// Single rays use backend/cpu/wide_bvh_traversal.h; batches trace runs of eight
// consecutive rays that share an octant as packets
// (backend/cpu/wide_bvh_packet_traversal.h) and every other ray singly.
#include <chrono>
#include <string>
#include <utility>

#include "backend/cpu/ray_batches.h"
#include "accel/accel_factories.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "backend/cpu/parallel.h"
#include "rayforge/core/error.h"
#include "backend/cpu/wide_bvh_packet_traversal.h"
#include "backend/cpu/wide_bvh_traversal.h"

namespace rf {

namespace {



template <int N>
class WideBvhAccel final : public Accel {
public:
    WideBvhAccel(WideBvh<N> bvh, std::string name, double build_ms, double layout_ms, double sah_cost,
                 double quality_cost)
        : bvh_(std::move(bvh)),
          name_(std::move(name)),
          build_ms_(build_ms),
          layout_ms_(layout_ms),
          sah_cost_(sah_cost),
          quality_cost_(quality_cost) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override { return wide_bvh_intersect(view(), ray); }
    [[nodiscard]] bool occluded(const Ray& ray) const override { return wide_bvh_occluded(view(), ray); }

    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override {
        check_batch_sizes("WideBvhAccel::intersect", rays.size(), hits.size());
        const WideBvhView<N> bvh = view();
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            size_t i = lo;
            for (; i + kRayPacketSize <= hi; i += kRayPacketSize) {
                if (rays_share_octant(&rays[i])) {
                    wide_bvh_intersect_packet(bvh, &rays[i], &hits[i]);
                } else {
                    for (size_t k = i; k < i + kRayPacketSize; ++k) hits[k] = wide_bvh_intersect(bvh, rays[k]);
                }
            }
            for (; i != hi; ++i) hits[i] = wide_bvh_intersect(bvh, rays[i]);
        });
    }

    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        check_batch_sizes("WideBvhAccel::occluded", rays.size(), occluded.size());
        const WideBvhView<N> bvh = view();
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            size_t i = lo;
            for (; i + kRayPacketSize <= hi; i += kRayPacketSize) {
                if (rays_share_octant(&rays[i])) {
                    wide_bvh_occluded_packet(bvh, &rays[i], &occluded[i]);
                } else {
                    for (size_t k = i; k < i + kRayPacketSize; ++k)
                        occluded[k] = wide_bvh_occluded(bvh, rays[k]) ? 1 : 0;
                }
            }
            for (; i != hi; ++i) occluded[i] = wide_bvh_occluded(bvh, rays[i]) ? 1 : 0;
        });
    }

    [[nodiscard]] AccelStats stats() const override {
        AccelStats s;
        s.name = name_;
        s.build_ms = build_ms_;
        s.layout_ms = layout_ms_;
        s.node_count = bvh_.nodes.size();
        s.leaf_count = bvh_.leaf_count;
        s.bytes = bvh_.memory_bytes();
        s.sah_cost = sah_cost_;
        s.quality_cost = quality_cost_;
        return s;
    }

    bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const override {
        const WideBvhView<N> bvh = view();
        totals += sum_traversal_counts(rays, [&](const Ray& ray, TraversalTotals& acc) {
            TraversalCounters counters;
            if (any_hit) (void)wide_bvh_occluded_counted(bvh, ray, counters);
            else (void)wide_bvh_intersect_counted(bvh, ray, counters);
            acc.steps += counters.nodes_visited;
            acc.prim_tests += counters.prims_tested;
        });
        return true;
    }

    [[nodiscard]] WideBvhView<N> view() const {
        return {bvh_.nodes.data(), bvh_.packs.data(), static_cast<uint32_t>(bvh_.nodes.size()), bvh_.coord_scale};
    }

private:
    WideBvh<N> bvh_;
    std::string name_;
    double build_ms_ = 0.0;
    double layout_ms_ = 0.0;
    double sah_cost_ = 0.0;
    double quality_cost_ = 0.0;
};

template <int N>
std::unique_ptr<Accel> make_accel(const SceneGeometry& geometry, const Bvh& bvh, double build_ms, std::string name) {
    // Quality is a property of the source binary tree, measured before collapsing.
    const double sah_cost = bvh.sah_cost(1.0f, 1.0f);
    const double quality_cost = bvh.quality_cost(2.0);
    const auto start = std::chrono::steady_clock::now();
    WideBvh<N> wide = collapse_bvh<N>(bvh, geometry.triangles);
    const double layout_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return std::make_unique<WideBvhAccel<N>>(std::move(wide), std::move(name), build_ms + layout_ms, layout_ms,
                                             sah_cost, quality_cost);
}

}  // namespace

std::unique_ptr<Accel> make_wide_bvh_accel(const SceneGeometry& geometry, Bvh bvh, const BuildOptions& options,
                                           double build_ms, std::string name) {
    switch (options.layout) {
        case Layout::Bvh4: return make_accel<4>(geometry, bvh, build_ms, std::move(name));
        case Layout::Bvh8: return make_accel<8>(geometry, bvh, build_ms, std::move(name));
        case Layout::Bvh2: break;
    }
    throw Error("make_wide_bvh_accel: layout " + to_string(options.layout) + " is not a wide layout");
}

}  // namespace rf
