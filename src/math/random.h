// Counter-based random numbers: every (pixel, sample, seed) owns a stream and
// its n-th number is a pure function of (stream, n). No state is shared
// between pixels, so an image is identical whatever the thread count or tile
// order, and the GPU backend can reproduce the CPU's numbers exactly.
//
// Hash: the PCG-based integer hash recommended by Jarzynski & Olano 2020,
// "Hash Functions for GPU Rendering" (JCGT 9(3)).
#pragma once

#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"

namespace rf {

RF_HDI uint32_t pcg_hash(uint32_t v) {
    uint32_t state = v * 747796405u + 2891336453u;
    uint32_t word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The 24 high bits of a hash as a float in [0, 1).
RF_HDI float hash_to_unit_float(uint32_t h) { return float(h >> 8) * (1.0f / 16777216.0f); }

class RandomStream {
public:
    // A placeholder (key 0) for arrays of per-path state; assign a real stream before use.
    RandomStream() = default;
    RF_HDI RandomStream(uint32_t pixel, uint32_t sample, uint32_t seed)
        : key_(pcg_hash(pixel ^ pcg_hash(sample ^ pcg_hash(seed)))) {}

    // The next dimension of this stream, uniform in [0, 1).
    RF_HDI float next() { return hash_to_unit_float(pcg_hash(key_ ^ pcg_hash(dimension_++))); }
    RF_HDI Vec2f next2() {
        float a = next();
        return {a, next()};
    }
    [[nodiscard]] RF_HDI uint32_t dimension() const { return dimension_; }

    // A new stream, independent of this one, keyed by this stream's key, its
    // current dimension and `tag`; this stream is left as it is. A consumer
    // that runs at another time than its place in the sample (a shadow ray
    // tested after the next bounce was drawn, as a wavefront does) takes its
    // numbers from such a stream, so they do not depend on when it runs.
    [[nodiscard]] RF_HDI RandomStream derive(uint32_t tag) const {
        return RandomStream(pcg_hash(key_ ^ pcg_hash(dimension_ ^ pcg_hash(tag ^ 0x9e3779b9u))));
    }

private:
    RF_HDI explicit RandomStream(uint32_t key) : key_(key) {}

    uint32_t key_ = 0;
    uint32_t dimension_ = 0;
};

}  // namespace rf
