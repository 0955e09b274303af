#include "accel/brute_force.h"

#include <limits>

namespace rf {
namespace {

AccelStats brute_force_stats() {
    AccelStats s;
    s.name = "brute";
    s.sah_cost = std::numeric_limits<double>::quiet_NaN();
    s.quality_cost = std::numeric_limits<double>::quiet_NaN();
    return s;
}

}  // namespace

BruteForceAccel::BruteForceAccel(const SceneGeometry& geometry)
    : ViewAccel(
          NoStructure{},
          [&](const NoStructure&) {
              return BruteForceTracer{geometry.triangles.data(), uint32_t(geometry.triangles.size())};
          },
          brute_force_stats()) {}

}  // namespace rf
