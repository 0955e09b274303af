#include "rayforge/math/affine.h"

#include <cmath>

#include "rayforge/core/error.h"

namespace rf {

Affine3f Affine3f::rotation(Vec3f axis, float radians) {
    Vec3f a = normalize(axis);
    float c = std::cos(radians), s = std::sin(radians), t = 1.0f - c;
    Affine3f r;
    r.m[0][0] = t * a.x * a.x + c;       r.m[0][1] = t * a.x * a.y - s * a.z; r.m[0][2] = t * a.x * a.z + s * a.y;
    r.m[1][0] = t * a.x * a.y + s * a.z; r.m[1][1] = t * a.y * a.y + c;       r.m[1][2] = t * a.y * a.z - s * a.x;
    r.m[2][0] = t * a.x * a.z - s * a.y; r.m[2][1] = t * a.y * a.z + s * a.x; r.m[2][2] = t * a.z * a.z + c;
    return r;
}

Affine3f Affine3f::from_column_major(const double* m16) {
    Affine3f a;
    for (int row = 0; row < 3; ++row)
        for (int col = 0; col < 4; ++col) a.m[row][col] = float(m16[col * 4 + row]);
    return a;
}

float Affine3f::determinant() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

Affine3f Affine3f::inverse() const {
    // Cofactors in double: transforms of scanned models can be badly scaled.
    double a[3][3];
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) a[r][c] = m[r][c];
    double det = a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
                 a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                 a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
    if (!std::isfinite(det) || std::fabs(det) < 1e-30) throw Error("transform is singular (determinant " + std::to_string(det) + ")");
    double inv[3][3];
    inv[0][0] = (a[1][1] * a[2][2] - a[1][2] * a[2][1]) / det;
    inv[0][1] = (a[0][2] * a[2][1] - a[0][1] * a[2][2]) / det;
    inv[0][2] = (a[0][1] * a[1][2] - a[0][2] * a[1][1]) / det;
    inv[1][0] = (a[1][2] * a[2][0] - a[1][0] * a[2][2]) / det;
    inv[1][1] = (a[0][0] * a[2][2] - a[0][2] * a[2][0]) / det;
    inv[1][2] = (a[0][2] * a[1][0] - a[0][0] * a[1][2]) / det;
    inv[2][0] = (a[1][0] * a[2][1] - a[1][1] * a[2][0]) / det;
    inv[2][1] = (a[0][1] * a[2][0] - a[0][0] * a[2][1]) / det;
    inv[2][2] = (a[0][0] * a[1][1] - a[0][1] * a[1][0]) / det;
    Affine3f r;
    for (int row = 0; row < 3; ++row) {
        double t = 0;
        for (int c = 0; c < 3; ++c) {
            r.m[row][c] = float(inv[row][c]);
            t -= inv[row][c] * m[c][3];
        }
        r.m[row][3] = float(t);
    }
    return r;
}

Affine3f Affine3f::normal_matrix() const {
    Affine3f inv = inverse();
    Affine3f n;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) n.m[r][c] = inv.m[c][r];
        n.m[r][3] = 0.0f;
    }
    return n;
}

Box3f Affine3f::transform_box(const Box3f& b) const {
    Box3f out;
    if (b.is_empty()) return out;
    for (int corner = 0; corner < 8; ++corner) {
        Vec3f p{(corner & 1) ? b.hi.x : b.lo.x, (corner & 2) ? b.hi.y : b.lo.y, (corner & 4) ? b.hi.z : b.lo.z};
        out.extend(transform_point(p));
    }
    return out;
}

Affine3f operator*(const Affine3f& a, const Affine3f& b) {
    Affine3f r;
    for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 4; ++col) {
            float v = a.m[row][0] * b.m[0][col] + a.m[row][1] * b.m[1][col] + a.m[row][2] * b.m[2][col];
            if (col == 3) v += a.m[row][3];
            r.m[row][col] = v;
        }
    }
    return r;
}

}  // namespace rf
