#include "accel/bvh/bvh_accel.h"

#include <chrono>

#include "accel/bvh/build/binned_sah.h"

namespace rf {

BvhAccel::BvhAccel(const SceneGeometry& geometry, const BuildOptions& options) : geometry_(geometry) {
    const auto start = std::chrono::steady_clock::now();
    switch (options.builder) {
        case Builder::BinnedSah: bvh_ = build_binned_sah(geometry.triangles, options); break;
    }
    build_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

AccelStats BvhAccel::stats() const {
    AccelStats s;
    s.name = "bvh/binned";
    s.build_ms = build_ms_;
    s.node_count = bvh_.nodes.size();
    s.leaf_count = bvh_.leaf_count();
    s.bytes = bvh_.memory_bytes();
    s.sah_cost = bvh_.sah_cost(1.0f, 1.0f);
    return s;
}

}  // namespace rf
