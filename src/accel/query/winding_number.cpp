// Generalised winding numbers (Jacobson, Kavan and Sorkine-Hornung, "Robust
// Inside-Outside Segmentation using Generalized Winding Numbers", SIGGRAPH
// 2013): w(q) = sum over triangles of their signed solid angle at q / 4 pi,
// each solid angle by van Oosterom and Strackee's formula ("The Solid Angle
// of a Plane Triangle", IEEE Trans. Biomed. Eng. 30(2), 1983). Evaluated
// hierarchically after Barill, Dickson, Schmidt, Levin and Jacobson, "Fast
// Winding Numbers for Soups and Clouds" (SIGGRAPH 2018), over the canonical
// BVH instead of their octree.
//
// The far field. With r = p - q for a node's area-weighted centroid p and
// y = x - p for a point x of its triangles, 4 pi w(q) = integral of
// n . k(r + y) dA with k(d) = d / |d|^3. Taylor's expansion of k at r to
// second order, k(r + y) = k(r) + J y + H[y, y] / 2 with
//   J_ij  = delta_ij / |r|^3 - 3 r_i r_j / |r|^5,
//   H_ijl = -3 (delta_ij r_l + delta_il r_j + delta_jl r_i) / |r|^5 + 15 r_i r_j r_l / |r|^7,
// integrates to three per-node sums: the dipole N = sum a n (Barill's
// first-order term), M1_ij = integral of n_i y_j (second order) and M2_ijl
// = integral of n_i y_j y_l (third order; the paper's "second order" counts
// from the dipole). J is symmetric and H fully symmetric, so only M1's trace
// and symmetric part S, M2's full symmetrisation T and its contraction t_l
// = sum_i T_iil survive:
//   4 pi w ~ (N . r + tr M1) / |r|^3 + (-3 r^T S r - 9/2 t . r) / |r|^5 + 15/2 T(r, r, r) / |r|^7.
// Per triangle the integrals are exact (n constant, integral of y = a (c - p),
// integral of y y^T = a (sum_k y_k y_k^T + s s^T) / 12 with y_k its vertices
// relative to p and s their sum); a parent's sums are its children's moved
// to its centroid (M1 += N d^T, M2_ijl += M1_ij d_l + M1_il d_j + N_i d_j d_l
// for d = child centroid - parent centroid), so a pass is linear in the
// triangles. The radius is exact at leaves (the farthest vertex) and above
// them the smaller of the children's balls grown by their offsets and the
// farthest corner of the node's vertex box. A node is used as a whole where
// |r| > beta * radius; Barill et al. show beta = 2 keeps the error small.
//
// Data layout: one 112-byte WindingNode per BVH node, in the BVH's node
// order (winding_number.h), the coefficients pre-multiplied so the
// evaluation is three polynomials and one square root. The sums are kept in
// double while they are accumulated (on the recursion's stack: O(depth)
// memory) and rounded to float once per node.
//
// Parallelism (TBB via core/parallel.h): the post-order recursion runs the
// two subtrees of the upper kParallelDepth levels as parallel tasks.
//
// Determinism: every node's sums come from its own triangles or its two
// children's sums in a fixed order, so the nodes are identical for every
// thread count; queries are evaluated one per thread, in a fixed traversal
// order.
#include "accel/query/winding_number.h"

#include <algorithm>
#include <cmath>

#include "core/parallel.h"

namespace rf::query {
namespace {

constexpr int kParallelDepth = 10;  // levels whose two subtrees run as tasks

// Index of the symmetric pair (j, l) in xx, yy, zz, xy, xz, yz.
constexpr int kPair[3][3] = {{0, 3, 4}, {3, 1, 5}, {4, 5, 2}};

struct Moments {
    double area = 0.0;
    double center[3] = {0, 0, 0};  // area-weighted centroid (the box centre where the area is 0)
    double n[3] = {0, 0, 0};       // sum of area-weighted normals
    double m1[3][3] = {};          // integral of n_i y_j
    double m2[3][6] = {};          // integral of n_i y_j y_l, (j, l) as kPair
    double radius = 0.0;           // every vertex lies within it of the centre
    Box3f box;                     // of every vertex (zero-area triangles' included)
};

void set_center(Moments& m, const double weighted[3]) {
    const Vec3f mid = m.box.center();
    for (int i = 0; i < 3; ++i) m.center[i] = m.area > 0.0 ? weighted[i] / m.area : double(mid[i]);
}

// The farthest corner of m.box from its centre.
double corner_radius(const Moments& m) {
    double sum = 0.0;
    for (int i = 0; i < 3; ++i) {
        const double d = std::max(std::fabs(double(m.box.lo[i]) - m.center[i]), std::fabs(double(m.box.hi[i]) - m.center[i]));
        sum += d * d;
    }
    return std::sqrt(sum);
}

Moments leaf_moments(std::span<const SlotTriangle> slots, std::span<const float> weights, uint32_t first,
                     uint32_t count) {
    Moments m;
    double weighted[3] = {0, 0, 0};
    for (uint32_t s = first; s < first + count; ++s) {
        const Triangle& t = slots[s].tri;
        m.box.extend(t.v0);
        m.box.extend(t.v1);
        m.box.extend(t.v2);
        if (slots[s].zero_area()) continue;
        const Vec3f an = t.geometric_normal();
        const double weight = weights.empty() ? 1.0 : double(weights[s]);
        const double area = 0.5 * weight * std::sqrt(double(an.x) * an.x + double(an.y) * an.y + double(an.z) * an.z);
        m.area += area;
        for (int i = 0; i < 3; ++i) weighted[i] += area * ((double(t.v0[i]) + t.v1[i] + t.v2[i]) / 3.0);
    }
    set_center(m, weighted);
    for (uint32_t s = first; s < first + count; ++s) {
        const Triangle& t = slots[s].tri;
        double y[3][3];
        const Vec3f* vertices[3] = {&t.v0, &t.v1, &t.v2};
        double radius2 = 0.0;
        for (int k = 0; k < 3; ++k) {
            for (int i = 0; i < 3; ++i) y[k][i] = double((*vertices[k])[i]) - m.center[i];
            radius2 = std::max(radius2, y[k][0] * y[k][0] + y[k][1] * y[k][1] + y[k][2] * y[k][2]);
        }
        m.radius = std::max(m.radius, std::sqrt(radius2));
        if (slots[s].zero_area()) continue;
        const double weight = weights.empty() ? 1.0 : double(weights[s]);
        const double e1[3] = {y[1][0] - y[0][0], y[1][1] - y[0][1], y[1][2] - y[0][2]};
        const double e2[3] = {y[2][0] - y[0][0], y[2][1] - y[0][1], y[2][2] - y[0][2]};
        const double an[3] = {0.5 * weight * (e1[1] * e2[2] - e1[2] * e2[1]), 0.5 * weight * (e1[2] * e2[0] - e1[0] * e2[2]),
                              0.5 * weight * (e1[0] * e2[1] - e1[1] * e2[0])};
        const double sum[3] = {y[0][0] + y[1][0] + y[2][0], y[0][1] + y[1][1] + y[2][1], y[0][2] + y[1][2] + y[2][2]};
        double second[6];  // integral of y_j y_l over the triangle, per unit area
        for (int j = 0; j < 3; ++j) {
            for (int l = j; l < 3; ++l) {
                double v = sum[j] * sum[l];
                for (int k = 0; k < 3; ++k) v += y[k][j] * y[k][l];
                second[kPair[j][l]] = v / 12.0;
            }
        }
        for (int i = 0; i < 3; ++i) {
            m.n[i] += an[i];
            for (int j = 0; j < 3; ++j) m.m1[i][j] += an[i] * sum[j] / 3.0;
            for (int p = 0; p < 6; ++p) m.m2[i][p] += an[i] * second[p];
        }
    }
    return m;
}

Moments combine(const Moments& a, const Moments& b) {
    Moments m;
    m.area = a.area + b.area;
    m.box = merge(a.box, b.box);
    double weighted[3];
    for (int i = 0; i < 3; ++i) weighted[i] = a.area * a.center[i] + b.area * b.center[i];
    set_center(m, weighted);
    double grown = 0.0;
    for (const Moments* c : {&a, &b}) {
        double d[3];
        for (int i = 0; i < 3; ++i) d[i] = c->center[i] - m.center[i];
        grown = std::max(grown, std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) + c->radius);
        for (int i = 0; i < 3; ++i) {
            m.n[i] += c->n[i];
            for (int j = 0; j < 3; ++j) m.m1[i][j] += c->m1[i][j] + c->n[i] * d[j];
            for (int j = 0; j < 3; ++j) {
                for (int l = j; l < 3; ++l) {
                    m.m2[i][kPair[j][l]] += c->m2[i][kPair[j][l]] + c->m1[i][j] * d[l] + c->m1[i][l] * d[j] +
                                            c->n[i] * d[j] * d[l];
                }
            }
        }
    }
    m.radius = std::min(grown, corner_radius(m));
    return m;
}

WindingNode to_node(const Moments& m) {
    WindingNode w;
    w.center = Vec3f(float(m.center[0]), float(m.center[1]), float(m.center[2]));
    // Rounded up, so that float rounding never lets a node count as far sooner.
    w.radius_squared = std::nextafter(float(m.radius * m.radius), kInfinity);
    w.normal = Vec3f(float(m.n[0]), float(m.n[1]), float(m.n[2]));
    w.trace1 = float(m.m1[0][0] + m.m1[1][1] + m.m1[2][2]);
    w.s[0] = float(-3.0 * m.m1[0][0]);
    w.s[1] = float(-3.0 * m.m1[1][1]);
    w.s[2] = float(-3.0 * m.m1[2][2]);
    w.s[3] = float(-3.0 * (m.m1[0][1] + m.m1[1][0]));
    w.s[4] = float(-3.0 * (m.m1[0][2] + m.m1[2][0]));
    w.s[5] = float(-3.0 * (m.m1[1][2] + m.m1[2][1]));
    // T_ijl = (M2_ijl + M2_jil + M2_lij) / 3 (M2 is symmetric in its last two indices).
    auto sym = [&](int i, int j, int l) {
        return (m.m2[i][kPair[j][l]] + m.m2[j][kPair[i][l]] + m.m2[l][kPair[i][j]]) / 3.0;
    };
    double t[3];
    for (int l = 0; l < 3; ++l) t[l] = sym(0, 0, l) + sym(1, 1, l) + sym(2, 2, l);
    w.t = Vec3f(float(-4.5 * t[0]), float(-4.5 * t[1]), float(-4.5 * t[2]));
    const double c = 7.5;
    w.cubic[0] = float(c * sym(0, 0, 0));
    w.cubic[1] = float(c * sym(1, 1, 1));
    w.cubic[2] = float(c * sym(2, 2, 2));
    w.cubic[3] = float(c * 3.0 * sym(0, 0, 1));
    w.cubic[4] = float(c * 3.0 * sym(0, 0, 2));
    w.cubic[5] = float(c * 3.0 * sym(0, 1, 1));
    w.cubic[6] = float(c * 3.0 * sym(1, 1, 2));
    w.cubic[7] = float(c * 3.0 * sym(0, 2, 2));
    w.cubic[8] = float(c * 3.0 * sym(1, 2, 2));
    w.cubic[9] = float(c * 6.0 * sym(0, 1, 2));
    return w;
}

struct Pass {
    const Bvh& bvh;
    std::span<const SlotTriangle> slots;
    std::span<const float> weights;
    WindingNode* out;

    Moments run(uint32_t index, int depth) const {
        const BvhNode& node = bvh.nodes[index];
        Moments m;
        if (node.is_leaf()) {
            m = leaf_moments(slots, weights, node.first, node.count);
        } else {
            Moments left, right;
            if (depth < kParallelDepth) {
                parallel::invoke([&] { left = run(node.first, depth + 1); },
                                 [&] { right = run(node.first + 1, depth + 1); });
            } else {
                left = run(node.first, depth + 1);
                right = run(node.first + 1, depth + 1);
            }
            m = combine(left, right);
        }
        out[index] = to_node(m);
        return m;
    }
};

}  // namespace

void compute_winding_nodes(const Bvh& bvh, std::span<const SlotTriangle> slots, std::span<const float> slot_weights,
                           std::vector<WindingNode>& nodes) {
    nodes.resize(bvh.nodes.size());
    if (bvh.nodes.empty()) return;
    Pass{bvh, slots, slot_weights, nodes.data()}.run(0, 0);
}

}  // namespace rf::query
