// The per-warp step of persistent threads with dynamic fetch (Aila and
// Laine 2009, sec. 3; Aila, Laine and Karras 2012), written for the host and
// the device so that the schedule can be replayed on the CPU
// (tests/cwbvh_fma_device_logic_test.cpp): each pass, a ballot gives the
// mask of the warp's lanes without a ray, one lane takes popc(mask) rays
// with one atomicAdd on the global ray counter, and every such lane takes
// the ray base + (its rank among them).
#pragma once

#include <cstdint>

#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/host_device.h"

namespace rf {

// The ray of lane `lane` in a fetch: `needing` the ballot of lanes without a
// ray (bit `lane` set), `base` the value the warp's atomicAdd returned.
RF_HDI uint32_t persistent_fetch_ray(uint32_t base, uint32_t needing, uint32_t lane) {
    return base + cwbvh_popc(needing & ((1u << lane) - 1u));
}

}  // namespace rf
