// What every BVH builder reads of rf::BuildOptions: the leaf size and the
// SAH's costs, and where to count its progress. build_bvh (the one
// dispatch) fills it; a builder's own options group (BinnedSahOptions,
// PlocOptions, ...) comes alongside.
#pragma once

#include "core/progress_meter.h"
#include "rayforge/accel/accel.h"

namespace rf {

struct BvhBuildConfig {
    int max_leaf_size = 4;  // leaves never hold more primitives than this
    SahCosts sah;           // every SAH decision: splits, leaf collapse
    // Counts the references placed in leaves, where a builder reports
    // progress (the top-down SAH builders); nullptr = nobody asked.
    ProgressMeter* progress = nullptr;
};

inline BvhBuildConfig bvh_build_config(const BuildOptions& options, ProgressMeter* progress = nullptr) {
    return {options.max_leaf_size, options.sah, progress};
}

}  // namespace rf
