#include "accel/bvh/builders/build_bvh.h"

#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/ploc.h"
#include "accel/bvh/builders/sbvh.h"
#include "accel/bvh/builders/sweep_sah.h"
#include "accel/bvh/optimize/reinsertion.h"
#include "rayforge/core/error.h"

namespace rf {

Bvh build_bvh_on_cpu(std::span<const Triangle> triangles, const BuildOptions& options) {
    Bvh bvh;
    switch (options.builder) {
        case Builder::BinnedSah: bvh = build_binned_sah(triangles, options); break;
        case Builder::SweepSah: bvh = build_sweep_sah(triangles, options); break;
        case Builder::Sbvh: bvh = build_sbvh(triangles, options); break;
        case Builder::Lbvh30: bvh = build_lbvh(triangles, options, 30); break;
        case Builder::Lbvh63: bvh = build_lbvh(triangles, options, 63); break;
        case Builder::Hlbvh2: bvh = build_hlbvh2(triangles, options); break;
        case Builder::GridBvh: bvh = build_grid_bvh(triangles, options, false); break;
        case Builder::GridBvhSplit: bvh = build_grid_bvh(triangles, options, true); break;
        case Builder::Ploc: bvh = build_ploc(triangles, options); break;
        default: throw Error("build_bvh: unknown builder");
    }
    if (options.optimize) optimize_reinsertion(bvh, triangles, options);
    return bvh;
}

}  // namespace rf
