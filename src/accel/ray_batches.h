// What every structure's batched queries share: the grain of the parallel
// loops over rays and the check that results have one slot per ray.
#pragma once

#include <cstddef>
#include <string>

#include "rayforge/core/error.h"

namespace rf {

inline constexpr size_t kRayGrainSize = 256;  // rays per parallel task

inline void check_batch_sizes(const char* what, size_t rays, size_t results) {
    if (rays != results) {
        throw Error(std::string(what) + ": " + std::to_string(rays) + " rays but " + std::to_string(results) +
                    " result slots");
    }
}

}  // namespace rf
