// rf::Accel over the 4- and 8-wide BVH layouts (accel/bvh/layout/wide_bvh.h),
// collapsed from the canonical binary BVH (Wald, Benthin and Boulos 2008),
// traced by backend/cpu/wide_bvh_tracer.h (single rays, and packets of eight
// in batches) through accel/view_accel.h.
#include <chrono>
#include <string>
#include <utility>

#include "accel/accel_factories.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel/view_accel.h"
#include "backend/cpu/wide_bvh_tracer.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

template <int N>
std::unique_ptr<Accel> make_accel(const SceneGeometry& geometry, const Bvh& bvh, double build_ms, std::string name) {
    // Quality is a property of the source binary tree, measured before collapsing.
    const double sah_cost = bvh.sah_cost(1.0f, 1.0f);
    const double quality_cost = bvh.quality_cost(2.0);
    const auto start = std::chrono::steady_clock::now();
    WideBvh<N> wide = collapse_bvh<N>(bvh, geometry.triangles);
    const double layout_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    AccelStats stats;
    stats.name = std::move(name);
    stats.build_ms = build_ms + layout_ms;
    stats.layout_ms = layout_ms;
    stats.sah_cost = sah_cost;
    stats.quality_cost = quality_cost;
    const auto make_tracer = [](const WideBvh<N>& w) {
        return WideBvhTracer<N>{
            WideBvhView<N>{w.nodes.data(), w.packs.data(), static_cast<uint32_t>(w.nodes.size()), w.coord_scale}};
    };
    return std::make_unique<ViewAccel<WideBvh<N>, WideBvhTracer<N>>>(std::move(wide), make_tracer, std::move(stats));
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
