// Animation evaluation: tracks (step, linear with slerp, glTF cubic spline,
// BART's Kochanek-Bartels splines and squad) and Scene::set_time (node
// hierarchy, instances, vertex keyframes, morph targets, linear-blend
// skinning, the camera).
//
// Papers: the glTF 2.0 specification, appendix C (STEP, LINEAR, CUBICSPLINE);
// Lext, Assarsson and Möller, "A Benchmark for Animated Ray Tracing" (BART,
// IEEE CG&A 2001) and its reference code: Kochanek-Bartels tangents with
// Eberly's time-adjusted weights, squad over the same weights, consecutive
// inner quaternion keys on one hemisphere, the first and last keys only
// shaping the curve; Shoemake 1985 (slerp).
// Data: a track is flat floats, `width` per key (three groups per key for a
// cubic spline); deformed meshes are rewritten in place, morphs and skins
// from Animation::rest_positions / rest_normals.
// Parallelism: vertices in chunks (parallel::reduce; the reduction says
// whether any vertex moved); nodes, instances and tracks serially (few).
// Determinism: every value is computed by one thread from the same inputs,
// in the same order of operations, so results do not depend on the schedule.
#include "scene/animation_eval.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/scene/scene.h"

namespace rf {

namespace {

// ---- quaternions (w, x, y, z in double, as BART's reference code) ----

struct Quat {
    double w = 1, x = 0, y = 0, z = 0;
};
Quat operator*(const Quat& a, const Quat& b) {
    return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
            a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
Quat scaled(const Quat& q, double s) { return {q.w * s, q.x * s, q.y * s, q.z * s}; }
Quat added(const Quat& a, const Quat& b) { return {a.w + b.w, a.x + b.x, a.y + b.y, a.z + b.z}; }
double qdot(const Quat& a, const Quat& b) { return a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z; }
Quat conjugate(const Quat& q) { return {q.w, -q.x, -q.y, -q.z}; }
Quat qlog(const Quat& q) {  // unit q -> pure quaternion
    const double angle = std::acos(std::clamp(q.w, -1.0, 1.0));
    const double s = std::sin(angle);
    const double k = std::fabs(s) > 1e-9 ? angle / s : 1.0;
    return {0, q.x * k, q.y * k, q.z * k};
}
Quat qexp(const Quat& q) {  // pure q -> unit quaternion
    const double angle = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z);
    const double s = std::sin(angle);
    const double k = std::fabs(s) > 1e-9 ? s / angle : 1.0;
    return {std::cos(angle), q.x * k, q.y * k, q.z * k};
}
// BART's slerp: no shortest-path flip (squad's hemisphere handling is done on the keys).
Quat slerp_bart(double t, const Quat& p, const Quat& q) {
    const double angle = std::acos(std::clamp(qdot(p, q), -1.0, 1.0));
    const double s = std::sin(angle);
    if (std::fabs(s) < 1e-9) return p;
    return added(scaled(p, std::sin((1 - t) * angle) / s), scaled(q, std::sin(t * angle) / s));
}
// glTF's slerp: the shorter arc; nlerp when the keys (nearly) coincide.
Quat slerp_shortest(double t, const Quat& p, Quat q) {
    double d = qdot(p, q);
    if (d < 0) q = scaled(q, -1.0), d = -d;
    if (d > 1.0 - 1e-9) return added(scaled(p, 1 - t), scaled(q, t));
    const double angle = std::acos(std::min(d, 1.0));
    const double s = std::sin(angle);
    return added(scaled(p, std::sin((1 - t) * angle) / s), scaled(q, std::sin(t * angle) / s));
}
Quat normalized(const Quat& q) {
    const double n = std::sqrt(qdot(q, q));
    return n > 0 ? scaled(q, 1.0 / n) : Quat{};
}
Quat to_quat(const float* v) { return {v[3], v[0], v[1], v[2]}; }  // x, y, z, w floats
void from_quat(const Quat& q, float* out) {
    const Quat n = normalized(q);
    out[0] = float(n.x), out[1] = float(n.y), out[2] = float(n.z), out[3] = float(n.w);
}

// ---- key lookup ----

// The values of key i (the value group of a cubic-spline key).
const float* key_value(const Track& tr, size_t i) {
    const size_t w = size_t(tr.width);
    if (tr.interpolation == Interpolation::CubicSpline) return tr.values.data() + i * 3 * w + w;
    return tr.values.data() + i * w;
}
void copy_key(const Track& tr, size_t i, float* out, bool rotation) {
    const float* v = key_value(tr, i);
    if (rotation) from_quat(to_quat(v), out);
    else std::memcpy(out, v, sizeof(float) * size_t(tr.width));
}
// The last key at or before t (0 before the first).
size_t key_before(const std::vector<float>& times, float t) {
    const auto it = std::upper_bound(times.begin(), times.end(), t);
    return it == times.begin() ? 0 : size_t(it - times.begin()) - 1;
}

void evaluate_linear(const Track& tr, float t, float* out, bool rotation) {
    const size_t n = tr.key_count();
    if (!(t > tr.times[0])) return copy_key(tr, 0, out, rotation);
    if (!(t < tr.times[n - 1])) return copy_key(tr, n - 1, out, rotation);
    const size_t i = key_before(tr.times, t);
    const double u = (double(t) - tr.times[i]) / (double(tr.times[i + 1]) - tr.times[i]);
    const float *a = key_value(tr, i), *b = key_value(tr, i + 1);
    if (rotation) return from_quat(slerp_shortest(u, to_quat(a), to_quat(b)), out);
    for (int c = 0; c < tr.width; ++c) out[c] = float(a[c] * (1 - u) + b[c] * u);
}

// Hermite over (value, out-tangent) of key i and (value, in-tangent) of key i+1, tangents scaled by the interval.
void evaluate_cubic(const Track& tr, float t, float* out, bool rotation) {
    const size_t n = tr.key_count(), w = size_t(tr.width);
    if (!(t > tr.times[0])) return copy_key(tr, 0, out, rotation);
    if (!(t < tr.times[n - 1])) return copy_key(tr, n - 1, out, rotation);
    const size_t i = key_before(tr.times, t);
    const double td = double(tr.times[i + 1]) - tr.times[i], s = (double(t) - tr.times[i]) / td;
    const double s2 = s * s, s3 = s2 * s;
    const double h00 = 2 * s3 - 3 * s2 + 1, h10 = (s3 - 2 * s2 + s) * td, h01 = -2 * s3 + 3 * s2, h11 = (s3 - s2) * td;
    const float* k0 = tr.values.data() + i * 3 * w;  // in, value, out of key i
    const float* k1 = k0 + 3 * w;                    // in, value, out of key i+1
    for (size_t c = 0; c < w; ++c) out[c] = float(h00 * k0[w + c] + h10 * k0[2 * w + c] + h01 * k1[w + c] + h11 * k1[c]);
    if (rotation) from_quat(to_quat(out), out);
}

// ---- Kochanek-Bartels (BART) ----

struct KbWeights {
    double out0, out1, in0, in1;
};
// Tangent multipliers for the segment key[i0+1] -> key[i0+2] (Eberly's time adjustment).
KbWeights kb_weights(const Track& tr, size_t i0) {
    const float* k = tr.times.data() + i0;
    const Vec3f &a = tr.tcb[i0 + 1], &b = tr.tcb[i0 + 2];  // tension, continuity, bias
    auto ratio = [](double num, double den) { return den > 0.0 ? 2.0 * num / den : 0.0; };
    const double adj0 = ratio(double(k[2]) - k[1], double(k[2]) - k[0]);
    const double adj1 = ratio(double(k[2]) - k[1], double(k[3]) - k[1]);
    KbWeights w;
    w.out0 = 0.5 * adj0 * (1.0 - a.x) * (1.0 + a.y) * (1.0 + a.z);
    w.out1 = 0.5 * adj0 * (1.0 - a.x) * (1.0 - a.y) * (1.0 - a.z);
    w.in0 = 0.5 * adj1 * (1.0 - b.x) * (1.0 - b.y) * (1.0 + b.z);
    w.in1 = 0.5 * adj1 * (1.0 - b.x) * (1.0 + b.y) * (1.0 - b.z);
    return w;
}

// BART's segment search: the first key index i0 of the segment (the curve runs
// key i0+1 -> i0+2) and its parameter, clamped to the inner keys. Times that
// go back are taken as they come (the first segment that ends after t).
std::pair<size_t, double> kb_segment(const std::vector<float>& k, float t) {
    const size_t polys = k.size() - 3;
    if (!(k[1] < t)) return {0, 0.0};
    if (!(t < k[polys + 1])) return {polys - 1, 1.0};
    for (size_t i = 0; i < polys; ++i) {
        if (t < k[i + 2]) {
            const double range = double(k[i + 2]) - k[i + 1];
            return {i, range > 0 ? std::clamp((double(t) - k[i + 1]) / range, 0.0, 1.0) : 0.0};
        }
    }
    return {polys - 1, 1.0};
}

void kb_values(const Track& tr, float t, float* out) {
    auto [i, u] = kb_segment(tr.times, t);
    const KbWeights w = kb_weights(tr, i);
    const float *k0 = key_value(tr, i), *k1 = key_value(tr, i + 1), *k2 = key_value(tr, i + 2), *k3 = key_value(tr, i + 3);
    for (int c = 0; c < tr.width; ++c) {
        const double p0 = k0[c], p1 = k1[c], p2 = k2[c], p3 = k3[c];
        const double dp = p2 - p1;
        const double tout = w.out1 * dp + w.out0 * (p1 - p0);
        const double tin = w.in1 * (p3 - p2) + w.in0 * dp;
        const double c2 = 3 * dp - 2 * tout - tin;
        const double c3 = -2 * dp + tout + tin;
        out[c] = float(p1 + u * (tout + u * (c2 + u * c3)));
    }
}

// Keys i0..i0+3 as BART sees them: each inner key (1 .. n-2) moved to the
// hemisphere of the key before it, in order.
void kb_quats(const Track& tr, size_t i0, Quat q[4]) {
    const size_t n = tr.key_count();
    Quat prev;
    for (size_t i = 0; i <= i0 + 3; ++i) {
        Quat cur = to_quat(key_value(tr, i));
        if (i >= 2 && i + 1 < n && qdot(prev, cur) < 0.0) cur = scaled(cur, -1.0);
        if (i >= i0) q[i - i0] = cur;
        prev = cur;
    }
}

void kb_rotation(const Track& tr, float t, float* out) {
    auto [i, s] = kb_segment(tr.times, t);
    const KbWeights w = kb_weights(tr, i);
    Quat q[4];
    kb_quats(tr, i, q);
    const Quat logdq = qlog(conjugate(q[1]) * q[2]);
    const Quat tout = added(scaled(logdq, w.out1), scaled(qlog(conjugate(q[0]) * q[1]), w.out0));
    const Quat tin = added(scaled(logdq, w.in0), scaled(qlog(conjugate(q[2]) * q[3]), w.in1));
    const Quat a = q[1] * qexp(scaled(added(tout, scaled(logdq, -1.0)), 0.5));
    const Quat b = q[2] * qexp(scaled(added(logdq, scaled(tin, -1.0)), 0.5));
    from_quat(slerp_bart(2 * s * (1 - s), slerp_bart(s, q[1], q[2]), slerp_bart(s, a, b)), out);
}

}  // namespace

void evaluate_track(const Track& track, float t, float* out, bool rotation) {
    if (track.empty()) {  // the rest value of nothing: zeros, or the identity rotation
        std::fill(out, out + track.width, 0.0f);
        if (rotation) out[3] = 1.0f;
        return;
    }
    switch (track.interpolation) {
    case Interpolation::Step: return copy_key(track, key_before(track.times, t), out, rotation);
    case Interpolation::Linear: return evaluate_linear(track, t, out, rotation);
    case Interpolation::CubicSpline: return evaluate_cubic(track, t, out, rotation);
    case Interpolation::KochanekBartels:
        if (track.key_count() < 4) return evaluate_linear(track, t, out, rotation);  // BART needs 4; finalize says so
        return rotation ? kb_rotation(track, t, out) : kb_values(track, t, out);
    }
}

void evaluate_track(const Track& track, float t, float* out) { evaluate_track(track, t, out, track.width == 4); }

Affine3f quaternion_matrix(const float q4[4]) {
    const Quat q = normalized(to_quat(q4));
    const double w = q.w, x = q.x, y = q.y, z = q.z;
    Affine3f r;
    r.m[0][0] = float(1 - 2 * (y * y + z * z)), r.m[0][1] = float(2 * (x * y - w * z)), r.m[0][2] = float(2 * (x * z + w * y));
    r.m[1][0] = float(2 * (x * y + w * z)), r.m[1][1] = float(1 - 2 * (x * x + z * z)), r.m[1][2] = float(2 * (y * z - w * x));
    r.m[2][0] = float(2 * (x * z - w * y)), r.m[2][1] = float(2 * (y * z + w * x)), r.m[2][2] = float(1 - 2 * (x * x + y * y));
    return r;
}

Vec4f axis_angle_quaternion(double ax, double ay, double az, double radians) {
    const double len = std::sqrt(ax * ax + ay * ay + az * az);
    if (!(len > 0.0)) return Vec4f{0, 0, 0, 1};
    const double s = std::sin(radians / 2) / len;
    return Vec4f{float(ax * s), float(ay * s), float(az * s), float(std::cos(radians / 2))};
}

Affine3f node_local_transform(const AnimatedNode& node, float t) {
    if (node.matrix) return *node.matrix;
    float tr[3] = {node.translation.x, node.translation.y, node.translation.z};
    float q[4] = {node.rotation.x, node.rotation.y, node.rotation.z, node.rotation.w};
    float s[3] = {node.scale.x, node.scale.y, node.scale.z};
    if (!node.translation_track.empty()) evaluate_track(node.translation_track, t, tr, false);
    if (!node.rotation_track.empty()) evaluate_track(node.rotation_track, t, q, true);
    if (!node.scale_track.empty()) evaluate_track(node.scale_track, t, s, false);
    return Affine3f::translation({tr[0], tr[1], tr[2]}) * quaternion_matrix(q) * Affine3f::scale({s[0], s[1], s[2]});
}

bool node_visible(const AnimatedNode& node, float t) {
    if (node.visibility.empty()) return true;
    float v = 1.0f;
    evaluate_track(node.visibility, t, &v, false);
    return v >= 0.5f;
}

namespace {

// ---- Scene::set_time ----

struct NodeStates {
    std::vector<Affine3f> world;
    std::vector<char> visible;
};

// Parents come before their children (finalize checks it).
NodeStates evaluate_nodes(const Animation& anim, float t) {
    NodeStates s;
    s.world.resize(anim.nodes.size());
    s.visible.resize(anim.nodes.size());
    for (size_t i = 0; i < anim.nodes.size(); ++i) {
        const AnimatedNode& node = anim.nodes[i];
        const Affine3f local = node_local_transform(node, t);
        const bool vis = node_visible(node, t);
        const bool root = node.parent < 0 || size_t(node.parent) >= i;
        s.world[i] = root ? local : s.world[size_t(node.parent)] * local;
        s.visible[i] = char(vis && (root || s.visible[size_t(node.parent)]));
    }
    return s;
}

bool same_transform(const Affine3f& a, const Affine3f& b) { return std::memcmp(a.m, b.m, sizeof(a.m)) == 0; }

void move_instances(Scene& scene, const NodeStates& nodes, bool first, GeometryChange& change) {
    for (const InstanceAnimation& ia : scene.animation.instances) {
        if (ia.instance >= scene.instances.size() || ia.node >= nodes.world.size()) continue;
        Instance& inst = scene.instances[ia.instance];
        const Affine3f m = nodes.world[ia.node] * ia.local;
        const bool vis = nodes.visible[ia.node] != 0;
        if (first || !same_transform(m, inst.transform) || vis != inst.visible) change.instances.push_back(ia.instance);
        inst.transform = m;
        inst.visible = vis;
    }
}

constexpr size_t kVertexGrain = 4096;

// Writes value(v) into out[v] for every vertex in parallel; true when any changed.
template <class Value>
bool write_vertices(std::vector<Vec3f>& out, Value&& value) {
    return parallel::reduce(
        size_t(0), out.size(), kVertexGrain, false,
        [&](size_t lo, size_t hi, bool changed) {
            for (size_t v = lo; v < hi; ++v) {
                const Vec3f p = value(v);
                changed = changed || !(p == out[v]);
                out[v] = p;
            }
            return changed;
        },
        [](bool a, bool b) { return a || b; });
}

Vec3f unit_or_self(Vec3f n) {
    const float len = length(n);
    return len > 0.0f ? n / len : n;
}

bool apply_vertex_keyframes(Mesh& mesh, const VertexKeyframes& vk, float t) {
    if (vk.times.empty()) return false;
    const size_t n = vk.times.size();
    size_t a = key_before(vk.times, t), b = a;
    float w = 0.0f;
    if (vk.interpolation != Interpolation::Step && t > vk.times[0] && a + 1 < n) {
        b = a + 1;
        w = float((double(t) - vk.times[a]) / (double(vk.times[b]) - vk.times[a]));
    }
    const std::vector<Vec3f> &pa = vk.positions[a], &pb = vk.positions[b];
    bool changed = write_vertices(mesh.positions, [&](size_t v) { return pa[v] * (1.0f - w) + pb[v] * w; });
    if (vk.normals.size() == n) {
        mesh.normals.resize(mesh.positions.size());
        const std::vector<Vec3f> &na = vk.normals[a], &nb = vk.normals[b];
        changed |= write_vertices(mesh.normals, [&](size_t v) { return unit_or_self(na[v] * (1.0f - w) + nb[v] * w); });
    }
    return changed;
}

// Morph weights at t: the track, else the defaults, else zeros.
std::vector<float> morph_weights(const MorphTargets& morph, float t) {
    std::vector<float> w(morph.position_deltas.size(), 0.0f);
    if (!morph.weights.empty() && size_t(morph.weights.width) == w.size()) evaluate_track(morph.weights, t, w.data(), false);
    else if (morph.default_weights.size() == w.size()) w = morph.default_weights;
    return w;
}

// What deforms one mesh: its morph targets and weights, its skin's joint matrices.
struct Deformer {
    const MorphTargets* morph = nullptr;
    std::vector<float> weights;
    const Skin* skin = nullptr;
    std::vector<Affine3f> joints;  // world(joint) * inverse_bind
};

// The skin's blended matrix at vertex v.
Affine3f blend_joints(const Deformer& d, size_t v) {
    Affine3f m;
    std::memset(m.m, 0, sizeof(m.m));
    const std::array<uint16_t, 4>& jv = d.skin->vertex_joints[v];
    const Vec4f wv = d.skin->vertex_weights[v];
    const float w[4] = {wv.x, wv.y, wv.z, wv.w};
    for (int j = 0; j < 4; ++j) {
        if (w[j] == 0.0f) continue;
        const Affine3f& jm = d.joints[jv[size_t(j)]];
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 4; ++c) m.m[r][c] += w[j] * jm.m[r][c];
    }
    return m;
}

// Cofactor matrix (det * inverse transpose) applied to n, signed so that mirrors keep the side.
Vec3f cofactor_times(const Affine3f& a, Vec3f n) {
    const Vec3f r0{a.m[0][0], a.m[0][1], a.m[0][2]}, r1{a.m[1][0], a.m[1][1], a.m[1][2]}, r2{a.m[2][0], a.m[2][1], a.m[2][2]};
    const Vec3f c0 = cross(r1, r2), c1 = cross(r2, r0), c2 = cross(r0, r1);  // rows of the cofactor matrix's transpose
    const Vec3f out = c0 * n.x + c1 * n.y + c2 * n.z;
    return dot(r0, c0) < 0.0f ? -out : out;
}

bool deform_mesh(Mesh& mesh, const std::vector<Vec3f>& rest_p, const std::vector<Vec3f>& rest_n, const Deformer& d) {
    auto morphed = [&](const std::vector<Vec3f>& rest, bool normals, size_t v) {
        Vec3f p = rest[v];
        if (!d.morph) return p;
        const auto& deltas = normals ? d.morph->normal_deltas : d.morph->position_deltas;
        if (deltas.size() != d.weights.size()) return p;
        for (size_t i = 0; i < deltas.size(); ++i)
            if (d.weights[i] != 0.0f) p += deltas[i][v] * d.weights[i];
        return p;
    };
    bool changed = write_vertices(mesh.positions, [&](size_t v) {
        const Vec3f p = morphed(rest_p, false, v);
        return d.skin ? blend_joints(d, v).transform_point(p) : p;
    });
    if (rest_n.size() == mesh.positions.size()) {
        mesh.normals.resize(rest_n.size());
        changed |= write_vertices(mesh.normals, [&](size_t v) {
            const Vec3f n = morphed(rest_n, true, v);
            return unit_or_self(d.skin ? cofactor_times(blend_joints(d, v), n) : n);
        });
    }
    return changed;
}

void capture_rest(Scene& scene, uint32_t mesh) {
    Animation& anim = scene.animation;
    anim.rest_positions.resize(scene.meshes.size());
    anim.rest_normals.resize(scene.meshes.size());
    if (anim.rest_positions[mesh].empty()) {
        anim.rest_positions[mesh] = scene.meshes[mesh].positions;
        anim.rest_normals[mesh] = scene.meshes[mesh].normals;
    }
}

std::vector<Deformer> deformers(Scene& scene, const NodeStates& nodes, float t) {
    std::vector<Deformer> d(scene.meshes.size());
    for (const MorphTargets& m : scene.animation.morphs)
        if (m.mesh < d.size()) d[m.mesh].morph = &m, d[m.mesh].weights = morph_weights(m, t);
    for (const Skin& s : scene.animation.skins) {
        if (s.mesh >= d.size()) continue;
        d[s.mesh].skin = &s;
        for (size_t j = 0; j < s.joints.size(); ++j)
            d[s.mesh].joints.push_back(nodes.world[s.joints[j]] * s.inverse_bind[j]);
    }
    return d;
}

void deform_meshes(Scene& scene, const NodeStates& nodes, float t, bool first, GeometryChange& change) {
    Animation& anim = scene.animation;
    for (const VertexKeyframes& vk : anim.vertex_keyframes)
        if (vk.mesh < scene.meshes.size() && (apply_vertex_keyframes(scene.meshes[vk.mesh], vk, t) || first))
            change.meshes.push_back(vk.mesh);
    if (anim.morphs.empty() && anim.skins.empty()) return;
    const std::vector<Deformer> d = deformers(scene, nodes, t);
    for (uint32_t m = 0; m < d.size(); ++m) {
        if (!d[m].morph && !d[m].skin) continue;
        capture_rest(scene, m);
        if (deform_mesh(scene.meshes[m], anim.rest_positions[m], anim.rest_normals[m], d[m]) || first)
            change.meshes.push_back(m);
    }
}

bool same_camera(const Camera& a, const Camera& b) {
    return a.eye == b.eye && a.target == b.target && a.up == b.up && a.vfov_degrees == b.vfov_degrees;
}

void move_camera(Scene& scene, const NodeStates& nodes, float t, bool first, GeometryChange& change) {
    CameraAnimation& ca = *scene.animation.camera;
    if (!ca.rest) ca.rest = scene.camera_or_default();
    Camera c = *ca.rest;
    if (ca.node >= 0 && size_t(ca.node) < nodes.world.size()) {
        const Affine3f& w = nodes.world[size_t(ca.node)];
        c.eye = w.transform_point(c.eye), c.target = w.transform_point(c.target), c.up = w.transform_vector(c.up);
    }
    auto vec3 = [&](const Track& tr, Vec3f& v) {
        if (!tr.empty() && tr.width == 3) evaluate_track(tr, t, &v.x, false);
    };
    vec3(ca.eye, c.eye), vec3(ca.target, c.target), vec3(ca.up, c.up);
    if (!ca.vfov_degrees.empty() && ca.vfov_degrees.width == 1) evaluate_track(ca.vfov_degrees, t, &c.vfov_degrees, false);
    change.camera = first || !scene.camera || !same_camera(c, *scene.camera);
    scene.camera = c;
}

void sort_unique(std::vector<uint32_t>& v) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
}

}  // namespace

GeometryChange Scene::set_time(float t) {
    GeometryChange change;
    time = t;
    if (animation.empty()) return change;
    const bool first = !animation.evaluated;
    const NodeStates nodes = evaluate_nodes(animation, t);
    move_instances(*this, nodes, first, change);
    deform_meshes(*this, nodes, t, first, change);
    sort_unique(change.meshes);
    if (!change.meshes.empty())  // a deformed mesh moves every instance of it
        for (uint32_t i = 0; i < instances.size(); ++i)
            if (std::binary_search(change.meshes.begin(), change.meshes.end(), instances[i].mesh))
                change.instances.push_back(i);
    sort_unique(change.instances);
    if (animation.camera) move_camera(*this, nodes, t, first, change);
    animation.evaluated = true;
    return change;
}

int Animation::frame_count() const { return animation_frame_count(start, end, frames_per_second); }

int animation_frame_count(float start, float end, float frames_per_second) {
    const double frames = (double(end) - double(start)) * double(frames_per_second);
    if (!(frames > 0.0)) return 1;
    return int(std::min(std::floor(frames + 1e-3) + 1.0, double(std::numeric_limits<int>::max())));
}

}  // namespace rf

// ---- validation (Scene::finalize) ----

namespace rf {

namespace {

[[noreturn]] void fail(const std::string& what, const std::string& reason) {
    throw Error("animation: " + what + ": " + reason);
}

bool finite(const std::vector<float>& v) {
    return std::all_of(v.begin(), v.end(), [](float x) { return std::isfinite(x); });
}

// `width` 0: any width. BART's spline keys may repeat or go back in time (its
// files do; the segment search copes), every other track's times increase.
void check_track(const Track& tr, const std::string& what, int width) {
    if (tr.empty()) return;
    if (tr.width < 1 || (width > 0 && tr.width != width))
        fail(what, "width " + std::to_string(tr.width) + ", expected " + std::to_string(width));
    const size_t groups = tr.interpolation == Interpolation::CubicSpline ? 3 : 1;
    if (tr.values.size() != tr.key_count() * groups * size_t(tr.width))
        fail(what, std::to_string(tr.values.size()) + " values for " + std::to_string(tr.key_count()) + " keys of width " +
                       std::to_string(tr.width));
    if (!finite(tr.times)) fail(what, "a key time is not finite");
    if (!finite(tr.values)) fail(what, "a key value is not finite");
    if (tr.interpolation == Interpolation::KochanekBartels) {
        if (tr.tcb.size() != tr.key_count()) fail(what, "needs one tension/continuity/bias per key");
        if (tr.key_count() < 4) fail(what, "a Kochanek-Bartels track needs at least 4 keys");
        for (const Vec3f& k : tr.tcb)
            if (!is_finite(k)) fail(what, "a tension/continuity/bias is not finite");
        return;
    }
    for (size_t k = 1; k < tr.key_count(); ++k)
        if (!(tr.times[k] > tr.times[k - 1])) fail(what, "key times must increase (key " + std::to_string(k) + ")");
}

void check_nodes(const Animation& anim) {
    for (size_t i = 0; i < anim.nodes.size(); ++i) {
        const AnimatedNode& n = anim.nodes[i];
        const std::string what = "node " + std::to_string(i) + (n.name.empty() ? "" : " '" + n.name.substr(0, 64) + "'");
        if (n.parent < -1 || n.parent >= int64_t(i)) fail(what, "parent " + std::to_string(n.parent) + " is not an earlier node");
        check_track(n.translation_track, what + " translation", 3);
        check_track(n.rotation_track, what + " rotation", 4);
        check_track(n.scale_track, what + " scale", 3);
        check_track(n.visibility, what + " visibility", 1);
        const float rest[10] = {n.translation.x, n.translation.y, n.translation.z, n.rotation.x, n.rotation.y,
                                n.rotation.z,    n.rotation.w,    n.scale.x,       n.scale.y,    n.scale.z};
        if (!finite(std::vector<float>(rest, rest + 10))) fail(what, "rest transform is not finite");
    }
}

// The index of a mesh-deforming entry, checked against the scene; at most one of each kind per mesh.
void check_mesh_index(uint32_t mesh, const Scene& scene, const std::string& what, std::vector<char>& seen) {
    if (mesh >= scene.meshes.size())
        fail(what, "mesh " + std::to_string(mesh) + " of " + std::to_string(scene.meshes.size()));
    if (seen[mesh]) fail(what, "mesh " + std::to_string(mesh) + " has two of these");
    seen[mesh] = 1;
}

void check_vertex_arrays(const std::vector<std::vector<Vec3f>>& arrays, size_t vertices, const std::string& what) {
    for (size_t k = 0; k < arrays.size(); ++k) {
        if (arrays[k].size() != vertices)
            fail(what, "entry " + std::to_string(k) + " has " + std::to_string(arrays[k].size()) + " vertices, the mesh " +
                           std::to_string(vertices));
        for (const Vec3f& p : arrays[k])
            if (!is_finite(p)) fail(what, "entry " + std::to_string(k) + " has a coordinate that is not finite");
    }
}

void check_vertex_keyframes(const Scene& scene) {
    std::vector<char> seen(scene.meshes.size(), 0);
    for (size_t i = 0; i < scene.animation.vertex_keyframes.size(); ++i) {
        const VertexKeyframes& vk = scene.animation.vertex_keyframes[i];
        const std::string what = "vertex keyframes " + std::to_string(i);
        check_mesh_index(vk.mesh, scene, what, seen);
        if (vk.interpolation != Interpolation::Step && vk.interpolation != Interpolation::Linear)
            fail(what, "interpolation must be step or linear");
        if (vk.times.empty() || vk.positions.size() != vk.times.size())
            fail(what, std::to_string(vk.positions.size()) + " position sets for " + std::to_string(vk.times.size()) + " times");
        if (!vk.normals.empty() && vk.normals.size() != vk.times.size())
            fail(what, std::to_string(vk.normals.size()) + " normal sets for " + std::to_string(vk.times.size()) + " times");
        Track times;
        times.width = 1;
        times.times = vk.times;
        times.values.assign(vk.times.size(), 0.0f);
        check_track(times, what, 1);
        const size_t n = scene.meshes[vk.mesh].vertex_count();
        check_vertex_arrays(vk.positions, n, what + " positions");
        check_vertex_arrays(vk.normals, n, what + " normals");
    }
}

void check_morphs(const Scene& scene) {
    std::vector<char> seen(scene.meshes.size(), 0);
    for (size_t i = 0; i < scene.animation.morphs.size(); ++i) {
        const MorphTargets& m = scene.animation.morphs[i];
        const std::string what = "morph targets " + std::to_string(i);
        check_mesh_index(m.mesh, scene, what, seen);
        const size_t targets = m.position_deltas.size(), n = scene.meshes[m.mesh].vertex_count();
        check_vertex_arrays(m.position_deltas, n, what + " positions");
        if (!m.normal_deltas.empty() && m.normal_deltas.size() != targets) fail(what, "normal deltas are not one per target");
        check_vertex_arrays(m.normal_deltas, n, what + " normals");
        if (!m.default_weights.empty() && m.default_weights.size() != targets) fail(what, "default weights are not one per target");
        if (!finite(m.default_weights)) fail(what, "a default weight is not finite");
        check_track(m.weights, what + " weights", int(targets));
    }
}

void check_skins(const Scene& scene) {
    std::vector<char> seen(scene.meshes.size(), 0);
    const Animation& anim = scene.animation;
    for (size_t i = 0; i < anim.skins.size(); ++i) {
        const Skin& s = anim.skins[i];
        const std::string what = "skin " + std::to_string(i);
        check_mesh_index(s.mesh, scene, what, seen);
        for (uint32_t j : s.joints)
            if (j >= anim.nodes.size()) fail(what, "joint node " + std::to_string(j) + " of " + std::to_string(anim.nodes.size()));
        if (s.inverse_bind.size() != s.joints.size()) fail(what, "inverse bind matrices are not one per joint");
        const size_t n = scene.meshes[s.mesh].vertex_count();
        if (s.vertex_joints.size() != n || s.vertex_weights.size() != n)
            fail(what, "joints and weights are not one per vertex (" + std::to_string(n) + ")");
        for (size_t v = 0; v < n; ++v) {
            const Vec4f w = s.vertex_weights[v];
            if (!is_finite(Vec3f{w.x, w.y, w.z}) || !std::isfinite(w.w)) fail(what, "vertex " + std::to_string(v) + ": weight is not finite");
            for (uint16_t j : s.vertex_joints[v])
                if (j >= s.joints.size()) fail(what, "vertex " + std::to_string(v) + ": joint " + std::to_string(j) + " of " + std::to_string(s.joints.size()));
        }
    }
}

void check_instances_and_camera(const Scene& scene) {
    const Animation& anim = scene.animation;
    for (size_t i = 0; i < anim.instances.size(); ++i) {
        const InstanceAnimation& ia = anim.instances[i];
        const std::string what = "instance animation " + std::to_string(i);
        if (ia.instance >= scene.instances.size())
            fail(what, "instance " + std::to_string(ia.instance) + " of " + std::to_string(scene.instances.size()));
        if (ia.node >= anim.nodes.size()) fail(what, "node " + std::to_string(ia.node) + " of " + std::to_string(anim.nodes.size()));
    }
    if (!anim.camera) return;
    const CameraAnimation& c = *anim.camera;
    if (c.node < -1 || c.node >= int64_t(anim.nodes.size()))
        fail("camera", "node " + std::to_string(c.node) + " of " + std::to_string(anim.nodes.size()));
    check_track(c.eye, "camera eye", 3);
    check_track(c.target, "camera target", 3);
    check_track(c.up, "camera up", 3);
    check_track(c.vfov_degrees, "camera fov", 1);
}

}  // namespace

void finalize_animation(Scene& scene) {
    Animation& anim = scene.animation;
    if (!std::isfinite(anim.start) || !std::isfinite(anim.end) || anim.end < anim.start)
        fail("time range", "start and end must be finite, start <= end");
    if (!(anim.frames_per_second > 0.0f) || !std::isfinite(anim.frames_per_second))
        fail("frames per second", "must be finite and positive");
    check_nodes(anim);
    check_instances_and_camera(scene);
    check_vertex_keyframes(scene);
    check_morphs(scene);
    check_skins(scene);
    std::vector<char> keyframed(scene.meshes.size(), 0);
    for (const VertexKeyframes& vk : anim.vertex_keyframes) keyframed[vk.mesh] = 1;
    for (const MorphTargets& m : anim.morphs)
        if (keyframed[m.mesh]) fail("mesh " + std::to_string(m.mesh), "has both vertex keyframes and morph targets");
    for (const Skin& s : anim.skins)
        if (keyframed[s.mesh]) fail("mesh " + std::to_string(s.mesh), "has both vertex keyframes and a skin");
    for (const MorphTargets& m : anim.morphs) capture_rest(scene, m.mesh);
    for (const Skin& s : anim.skins) capture_rest(scene, s.mesh);
    if (anim.camera && !anim.camera->rest) anim.camera->rest = scene.camera_or_default();
}

}  // namespace rf
