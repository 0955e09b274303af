// rf::Accel that tests every triangle: slow, obviously correct, the
// reference every other structure is checked against.
#pragma once

#include "accel/view_accel.h"

namespace rf {

class BruteForceAccel final : public ViewAccel<NoStructure, BruteForceTracer> {
public:
    // `geometry` must outlive this object.
    explicit BruteForceAccel(const SceneGeometry& geometry);
};

}  // namespace rf
