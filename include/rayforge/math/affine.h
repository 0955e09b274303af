// 3x4 affine transform (rotation/scale/shear + translation), row-major.
#pragma once

#include "rayforge/math/box.h"
#include "rayforge/math/vec.h"

namespace rf {

struct Affine3f {
    // Rows of the 3x3 linear part followed by the translation column.
    float m[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};

    RF_HDI static Affine3f identity() { return {}; }
    RF_HDI static Affine3f translation(Vec3f t) {
        Affine3f a; a.m[0][3] = t.x; a.m[1][3] = t.y; a.m[2][3] = t.z; return a;
    }
    RF_HDI static Affine3f scale(Vec3f s) {
        Affine3f a; a.m[0][0] = s.x; a.m[1][1] = s.y; a.m[2][2] = s.z; return a;
    }
    // Rotation by `radians` about a unit axis (right-handed).
    static Affine3f rotation(Vec3f axis, float radians);
    // From a column-major 4x4 matrix (glTF, OpenGL); the last row is ignored.
    static Affine3f from_column_major(const double* m16);

    RF_HDI Vec3f transform_point(Vec3f p) const {
        return {m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3],
                m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3],
                m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3]};
    }
    RF_HDI Vec3f transform_vector(Vec3f v) const {
        return {m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
                m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
                m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z};
    }
    [[nodiscard]] Affine3f inverse() const;   // throws rf::Error when singular
    [[nodiscard]] float determinant() const;
    // Normals transform by the inverse transpose of the linear part.
    [[nodiscard]] Affine3f normal_matrix() const;
    [[nodiscard]] Box3f transform_box(const Box3f& b) const;
};

// a * b: apply b first, then a.
Affine3f operator*(const Affine3f& a, const Affine3f& b);

}  // namespace rf
