// AFF keyframe animation, as in BART's reference code: transform blocks are
// T*R*S with translation and scale on Kochanek-Bartels splines, rotation a
// squad of quaternions over the same spline weights, and step visibility.
// The keys are kept as rf::Track (the scene model's tracks); the splines are
// evaluated by rf::evaluate_track (src/scene/animation.cpp), the one
// implementation of BART's math.
#pragma once

#include <string>

#include "rayforge/math/affine.h"
#include "rayforge/scene/animation.h"

namespace rf::io::aff {

// One `k name { ... }` block. transl and scale: KochanekBartels, width 3;
// rot: KochanekBartels, width 4, quaternions x, y, z, w from BART's axis and
// angle; visibility: Step, width 1, 0 or 1, starting with a visible key at the
// lowest float (BART: visible until the first key).
struct Animation {
    Track transl, rot, scale, visibility;
    std::string file;
    long line = 0;

    // An identity-rest node carrying these tracks.
    [[nodiscard]] AnimatedNode node(const std::string& name) const;
    [[nodiscard]] Affine3f matrix(double t) const;
    [[nodiscard]] bool visible(double t) const;
};

}  // namespace rf::io::aff
