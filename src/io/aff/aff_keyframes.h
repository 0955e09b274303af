// AFF keyframe animation, as in BART's reference code: transform blocks are
// T*R*S with translation and scale on Kochanek-Bartels splines, rotation a
// squad of quaternions over the same spline weights, and step visibility.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "rayforge/math/affine.h"
#include "rayforge/math/vec.h"

namespace rf::io::aff {

struct Quat {
    double w = 1, x = 0, y = 0, z = 0;
};

struct Key {
    double t = 0;
    double v[4] = {0, 0, 0, 0};  // xyz (transl, scale) or axis xyz + angle in radians (rot)
    double tension = 0, continuity = 0, bias = 0;
};

// The spline through `keys` (at least 4; the first and last only shape it) at time t.
Vec3f kb_position(const std::vector<Key>& keys, double t);
Quat kb_rotation(const std::vector<Key>& keys, double t);
Affine3f quat_matrix(Quat q);  // q normalised first

// One `k name { ... }` block.
struct Animation {
    std::vector<Key> transl, rot, scale;
    std::vector<std::pair<double, bool>> visibility;
    std::string file;
    long line = 0;

    [[nodiscard]] Affine3f matrix(double t) const;
    [[nodiscard]] bool visible(double t) const;
};

}  // namespace rf::io::aff
