// Evaluation of AFF keyframes: quaternion algebra, the Kochanek-Bartels
// spline weights of BART/Eberly, and an Animation's matrix and visibility.
#include "io/aff/aff_keyframes.h"

#include <algorithm>
#include <cmath>

namespace rf::io::aff {

namespace {

Quat operator*(const Quat& a, const Quat& b) {
    return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
Quat scaled(const Quat& q, double s) { return {q.w * s, q.x * s, q.y * s, q.z * s}; }
Quat added(const Quat& a, const Quat& b) { return {a.w + b.w, a.x + b.x, a.y + b.y, a.z + b.z}; }
double qdot(const Quat& a, const Quat& b) { return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z; }
Quat conjugate(const Quat& q) { return {q.w, -q.x, -q.y, -q.z}; }
Quat from_axis_angle(double ax, double ay, double az, double radians) {
    const double len = std::sqrt(ax * ax + ay * ay + az * az);
    if (!(len > 0.0)) return {};
    const double s = std::sin(radians / 2) / len;
    return {std::cos(radians / 2), ax * s, ay * s, az * s};
}
Quat qlog(const Quat& q) {  // unit q -> pure quaternion
    const double angle = std::acos(std::clamp(q.w, -1.0, 1.0));
    const double s = std::sin(angle);
    if (std::fabs(s) > 1e-9) {
        const double k = angle / s;
        return {0, q.x * k, q.y * k, q.z * k};
    }
    return {0, q.x, q.y, q.z};
}
Quat qexp(const Quat& q) {  // pure q -> unit quaternion
    const double angle = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    const double s = std::sin(angle);
    if (std::fabs(s) > 1e-9) {
        const double k = s / angle;
        return {std::cos(angle), q.x * k, q.y * k, q.z * k};
    }
    return {std::cos(angle), q.x, q.y, q.z};
}
Quat slerp(double t, const Quat& p, const Quat& q) {
    const double angle = std::acos(std::clamp(qdot(p, q), -1.0, 1.0));
    const double s = std::sin(angle);
    if (std::fabs(s) < 1e-9) return p;
    return added(scaled(p, std::sin((1 - t) * angle) / s), scaled(q, std::sin(t * angle) / s));
}

// Tangent multipliers of the BART/Eberly KB spline for the segment key[i1] -> key[i2].
struct KbWeights {
    double out0, out1, in0, in1;
};
KbWeights kb_weights(const std::vector<Key>& k, size_t i0) {
    const Key &k0 = k[i0], &k1 = k[i0 + 1], &k2 = k[i0 + 2], &k3 = k[i0 + 3];
    auto ratio = [](double num, double den) { return den > 0.0 ? 2.0 * num / den : 0.0; };
    const double adj0 = ratio(k2.t - k1.t, k2.t - k0.t);
    const double adj1 = ratio(k2.t - k1.t, k3.t - k1.t);
    KbWeights w;
    w.out0 = 0.5 * adj0 * (1 - k1.tension) * (1 + k1.continuity) * (1 + k1.bias);
    w.out1 = 0.5 * adj0 * (1 - k1.tension) * (1 - k1.continuity) * (1 - k1.bias);
    w.in0 = 0.5 * adj1 * (1 - k2.tension) * (1 - k2.continuity) * (1 + k2.bias);
    w.in1 = 0.5 * adj1 * (1 - k2.tension) * (1 + k2.continuity) * (1 - k2.bias);
    return w;
}

// The segment (first key index i0; the curve runs from key i0+1 to i0+2) and the
// parameter in [0,1] for time t, clamped to the inner keys.
std::pair<size_t, double> kb_segment(const std::vector<Key>& k, double t) {
    const size_t polys = k.size() - 3;
    if (!(k[1].t < t)) return {0, 0.0};
    if (!(t < k[polys + 1].t)) return {polys - 1, 1.0};
    for (size_t i = 0; i < polys; ++i) {
        if (t < k[i + 2].t) {
            const double range = k[i + 2].t - k[i + 1].t;
            return {i, range > 0 ? std::clamp((t - k[i + 1].t) / range, 0.0, 1.0) : 0.0};
        }
    }
    return {polys - 1, 1.0};
}

}  // namespace

Vec3f kb_position(const std::vector<Key>& k, double t) {
    auto [i, u] = kb_segment(k, t);
    const KbWeights w = kb_weights(k, i);
    double out[3];
    for (int c = 0; c < 3; ++c) {
        const double p0 = k[i].v[c], p1 = k[i + 1].v[c], p2 = k[i + 2].v[c], p3 = k[i + 3].v[c];
        const double dp = p2 - p1;
        const double tout = w.out1 * dp + w.out0 * (p1 - p0);
        const double tin = w.in1 * (p3 - p2) + w.in0 * dp;
        const double c2 = 3 * dp - 2 * tout - tin;
        const double c3 = -2 * dp + tout + tin;
        out[c] = p1 + u * (tout + u * (c2 + u * c3));
    }
    return {float(out[0]), float(out[1]), float(out[2])};
}

Quat kb_rotation(const std::vector<Key>& k, double t) {
    std::vector<Quat> q(k.size());
    for (size_t i = 0; i < k.size(); ++i) q[i] = from_axis_angle(k[i].v[0], k[i].v[1], k[i].v[2], k[i].v[3]);
    // Consecutive inner keys on the same hemisphere (as the reference code does).
    for (size_t i = 1; i + 2 < k.size(); ++i)
        if (qdot(q[i], q[i + 1]) < 0.0) q[i + 1] = scaled(q[i + 1], -1.0);
    auto [i, s] = kb_segment(k, t);
    const KbWeights w = kb_weights(k, i);
    const Quat &q0 = q[i], &q1 = q[i + 1], &q2 = q[i + 2], &q3 = q[i + 3];
    const Quat logdq = qlog(conjugate(q1) * q2);
    const Quat tout = added(scaled(logdq, w.out1), scaled(qlog(conjugate(q0) * q1), w.out0));
    const Quat tin = added(scaled(logdq, w.in0), scaled(qlog(conjugate(q2) * q3), w.in1));
    const Quat a = q1 * qexp(scaled(added(tout, scaled(logdq, -1.0)), 0.5));
    const Quat b = q2 * qexp(scaled(added(logdq, scaled(tin, -1.0)), 0.5));
    return slerp(2 * s * (1 - s), slerp(s, q1, q2), slerp(s, a, b));
}

Affine3f quat_matrix(Quat q) {
    const double n = std::sqrt(qdot(q, q));
    if (n > 0) q = scaled(q, 1.0 / n);
    Affine3f r;
    const double w = q.w, x = q.x, y = q.y, z = q.z;
    r.m[0][0] = float(1 - 2 * (y * y + z * z)); r.m[0][1] = float(2 * (x * y - w * z)); r.m[0][2] = float(2 * (x * z + w * y));
    r.m[1][0] = float(2 * (x * y + w * z)); r.m[1][1] = float(1 - 2 * (x * x + z * z)); r.m[1][2] = float(2 * (y * z - w * x));
    r.m[2][0] = float(2 * (x * z - w * y)); r.m[2][1] = float(2 * (y * z + w * x)); r.m[2][2] = float(1 - 2 * (x * x + y * y));
    return r;
}

Affine3f Animation::matrix(double t) const {
    Affine3f m = rot.empty() ? Affine3f::identity() : quat_matrix(kb_rotation(rot, t));
    if (!scale.empty()) m = m * Affine3f::scale(kb_position(scale, t));
    if (!transl.empty()) {
        const Vec3f p = kb_position(transl, t);
        m.m[0][3] = p.x;
        m.m[1][3] = p.y;
        m.m[2][3] = p.z;
    }
    return m;
}

bool Animation::visible(double t) const {
    bool visible = true;  // visible until the first key
    for (const auto& [time, flag] : visibility) {
        if (t < time) break;
        visible = flag;
    }
    return visible;
}

}  // namespace rf::io::aff
