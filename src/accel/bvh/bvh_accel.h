// rf::Accel over the canonical BVH, traversed by trace/bvh_traversal.h
// (accel/view_accel.h with the Bvh2Tracer).
#pragma once

#include <string>

#include "accel/view_accel.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf {

void describe_structure(const Bvh& bvh, AccelStats& stats);

class BvhAccel final : public ViewAccel<Bvh, Bvh2Tracer> {
public:
    // Traces `bvh`, built over `geometry` in `build_ms` by the builder `name`
    // describes (e.g. "bvh/binned/bvh2"); `geometry` must outlive this object.
    BvhAccel(const SceneGeometry& geometry, Bvh bvh, std::string name, double build_ms);

    [[nodiscard]] const Bvh& bvh() const { return structure(); }
    [[nodiscard]] BvhView view() const { return tracer().bvh; }
};

}  // namespace rf
