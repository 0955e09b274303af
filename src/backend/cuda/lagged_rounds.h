// A device loop driven by the host without a blocking read per step: the
// builders' iterations (PLOC) and queue levels (HLBVH2) whose next size
// only the device knows. Steps are launched in rounds, back to back; after
// each round one small value the device keeps (a count, a loop state) is
// copied asynchronously into pinned memory. The host waits only for the
// PREVIOUS round's copy, while the current round runs on the device, and
// stops once that copy says the loop is over; the steps of the round in
// flight then find nothing to do on the device and return at once. So
// every step's kernels must read their sizes from device memory and treat
// "done" as a no-op; the copies also bound the sizes of later grids.
// For .cu files only.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "backend/cuda/cuda_check.h"
#include "backend/cuda/device_buffer.h"
#include "backend/cuda/event_timer.h"

namespace rf::cuda {

// The pinned landing slots and events of the copies: made before a timed
// stage (page-locked allocations are slow), handed to the loop.
template <class T>
struct LaggedCopies {
    PinnedValues<T> seen{2};
    StreamEvent landed[2];
};

// launch_step(step, const T* seen, seen_step): launches step `step` (0, 1,
// ...); `seen` is the latest value the host has (null before the first
// arrives), the device's after `seen_step` steps.
// watched(launched): the device address of the value after `launched`
// steps. done(value): whether the loop is over once the device holds it.
// max_steps: a bound the loop does not reach unless the device misbehaves
// (the caller checks the final value on the device either way).
// Returns the steps launched.
template <class T, class LaunchStep, class Watched, class Done>
uint32_t launch_in_lagged_rounds(LaggedCopies<T>& copies, uint32_t per_round, uint32_t max_steps,
                                 LaunchStep&& launch_step, Watched&& watched, Done&& done) {
    PinnedValues<T>& seen = copies.seen;
    StreamEvent* landed = copies.landed;
    T latest{};
    bool have = false;
    uint32_t launched = 0, copied_at[2] = {0, 0}, latest_at = 0;
    for (uint32_t round = 0;; ++round) {
        for (uint32_t k = 0; k < per_round && launched < max_steps; ++k, ++launched) {
            launch_step(launched, have ? &latest : nullptr, latest_at);
        }
        copied_at[round & 1] = launched;
        RF_CUDA_CHECK(cudaMemcpyAsync(&seen[round & 1], watched(launched), sizeof(T), cudaMemcpyDeviceToHost));
        landed[round & 1].record();
        if (round > 0) {
            landed[(round - 1) & 1].synchronize();
            latest = seen[(round - 1) & 1];
            latest_at = copied_at[(round - 1) & 1];
            have = true;
            if (done(latest)) return launched;
        }
        if (launched >= max_steps) return launched;
    }
}

}  // namespace rf::cuda
