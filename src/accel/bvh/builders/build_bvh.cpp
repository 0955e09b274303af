#include "accel/bvh/builders/build_bvh.h"

#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/bvh_build_config.h"
#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/hlbvh2.h"
#include "accel/bvh/builders/hploc.h"
#include "accel/bvh/builders/lbvh.h"
#include "accel/bvh/builders/ploc.h"
#include "accel/bvh/builders/sbvh.h"
#include "accel/bvh/builders/sweep_sah.h"
#include "accel/bvh/optimize/reinsertion.h"
#include "accel/bvh/optimize/treelet_restructure.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

Bvh run_builder(std::span<const Triangle> triangles, const BuildOptions& options, ProgressMeter* progress) {
    const BvhBuildConfig config = bvh_build_config(options, progress);
    switch (options.builder) {
        case Builder::BinnedSah: return build_binned_sah(triangles, config, options.binned);
        case Builder::SweepSah: return build_sweep_sah(triangles, config);
        case Builder::Sbvh: return build_sbvh(triangles, config, options.sbvh);
        case Builder::Lbvh30: return build_lbvh(triangles, config, 30);
        case Builder::Lbvh63: return build_lbvh(triangles, config, 63);
        case Builder::Hlbvh2: return build_hlbvh2(triangles, config);
        case Builder::GridBvh: return build_grid_bvh(triangles, config, options.grid_bvh, false);
        case Builder::GridBvhSplit: return build_grid_bvh(triangles, config, options.grid_bvh, true);
        case Builder::Ploc: return build_ploc(triangles, config, options.ploc);
        case Builder::Hploc: return build_hploc(triangles, config, options.ploc);
    }
    throw Error("build_bvh: unknown builder");
}

}  // namespace

Bvh build_bvh_on_cpu(std::span<const Triangle> triangles, const BuildOptions& options, ProgressMeter* progress) {
    return parallel::with_threads(options.threads, [&] {
        Bvh bvh = run_builder(triangles, options, progress);
        if (options.treelets.enabled) optimize_treelets(bvh, triangles, bvh_build_config(options), options.treelets);
        if (options.reinsertion.enabled) optimize_reinsertion(bvh, triangles, options.sah, options.reinsertion);
        return bvh;
    });
}

}  // namespace rf
