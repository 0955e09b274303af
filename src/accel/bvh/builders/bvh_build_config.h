// What every BVH builder reads of rf::BuildOptions: the leaf size and the
// SAH's costs. build_bvh (the one dispatch) fills it; a builder's own
// options group (BinnedSahOptions, PlocOptions, ...) comes alongside.
#pragma once

#include "rayforge/accel/accel.h"

namespace rf {

struct BvhBuildConfig {
    int max_leaf_size = 4;  // leaves never hold more primitives than this
    SahCosts sah;           // every SAH decision: splits, leaf collapse
};

inline BvhBuildConfig bvh_build_config(const BuildOptions& options) {
    return {options.max_leaf_size, options.sah};
}

}  // namespace rf
