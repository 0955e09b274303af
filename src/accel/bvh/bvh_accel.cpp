#include "accel/bvh/bvh_accel.h"

#include <utility>

namespace rf {

void describe_structure(const Bvh& bvh, AccelStats& s) {
    s.node_count = bvh.nodes.size();
    s.leaf_count = bvh.leaf_count();
    s.bytes = bvh.memory_bytes();
    s.sah_cost = bvh.sah_cost(1.0f, 1.0f);
    s.quality_cost = bvh.quality_cost(2.0);
}

namespace {

AccelStats named(std::string name, double build_ms) {
    AccelStats s;
    s.name = std::move(name);
    s.build_ms = build_ms;
    return s;
}

}  // namespace

BvhAccel::BvhAccel(const SceneGeometry& geometry, Bvh bvh, std::string name, double build_ms)
    : ViewAccel(
          std::move(bvh),
          [&](const Bvh& b) {
              return Bvh2Tracer{BvhView{b.nodes.data(), b.prim_indices.data(), geometry.triangles.data(),
                                        static_cast<uint32_t>(b.nodes.size())}};
          },
          named(std::move(name), build_ms)) {}

}  // namespace rf
