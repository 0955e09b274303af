// rf::Accel that tests every triangle: slow, obviously correct, the
// reference every other structure is checked against.
#pragma once

#include "rayforge/accel/accel.h"

namespace rf {

class BruteForceAccel final : public Accel {
public:
    // `geometry` must outlive this object.
    explicit BruteForceAccel(const SceneGeometry& geometry) : geometry_(geometry) {}

    [[nodiscard]] Hit intersect(const Ray& ray) const override;
    [[nodiscard]] bool occluded(const Ray& ray) const override;
    using Accel::intersect;
    using Accel::occluded;
    [[nodiscard]] AccelStats stats() const override;

private:
    const SceneGeometry& geometry_;
};

}  // namespace rf
