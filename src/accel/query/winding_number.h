// Generalised winding numbers over a QueryView: the exact solid angle of a
// triangle, the per-node far-field expansion of Barill et al. 2018 and the
// traversal that sums them (winding_number.cpp computes the nodes; see its
// prologue for the derivation and the sources).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "accel/query/query_mesh.h"
#include "core/assert.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"

namespace rf::query {

inline constexpr float kInvFourPi = 0.0795774715459476679f;  // 1 / (4 pi)

// Signed solid angle of triangle (a, b, c) seen from q (van Oosterom and
// Strackee 1983): positive when q lies behind the triangle (on the side its
// normal cross(b - a, c - a) points away from), so the triangles of a
// closed outward-wound mesh sum to 4 pi at a point inside.
RF_HDI float triangle_solid_angle(Vec3f q, const Triangle& t) {
    const Vec3f a = t.v0 - q, b = t.v1 - q, c = t.v2 - q;
    const float la = length(a), lb = length(b), lc = length(c);
    const float det = dot(a, cross(b, c));
    const float den = la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la;
    return 2.0f * atan2f(det, den);
}

// One node's far field about its area-weighted centroid `center`, with the
// coefficients pre-multiplied so that, for r = center - q, 4 pi w(q) is
//   (dot(normal, r) + trace1) / |r|^3 + (r^T S r + dot(t, r)) / |r|^5 + T(r, r, r) / |r|^7.
// 112 bytes; the array is parallel to the BVH's nodes.
struct alignas(16) WindingNode {
    Vec3f center;
    float radius_squared = 0.0f;  // of a ball about `center` holding the node's triangles
    Vec3f normal;                 // sum of area-weighted normals (the dipole)
    float trace1 = 0.0f;          // trace of the first moment sum n (x - center)^T dA
    float s[6] = {};              // -3 x the symmetric first moment: xx, yy, zz, 2xy, 2xz, 2yz
    Vec3f t;                      // -9/2 x the contracted second moment
    float cubic[10] = {};         // 15/2 x the symmetrised second moment, times multiplicities:
                                  // xxx, yyy, zzz, xxy, xxz, xyy, yyz, xzz, yzz, xyz
};
static_assert(sizeof(WindingNode) == 112, "WindingNode layout");

// 4 pi times the node's expansion at q (r = center - q, r2 = |r|^2 > 0).
RF_HDI float expansion_times_four_pi(const WindingNode& w, Vec3f r, float r2) {
    const float inv_r2 = 1.0f / r2;
    const float inv_r3 = inv_r2 * sqrtf(inv_r2);
    const float inv_r5 = inv_r3 * inv_r2;
    const float x = r.x, y = r.y, z = r.z;
    const float order1 = dot(w.normal, r) + w.trace1;
    const float order2 = w.s[0] * x * x + w.s[1] * y * y + w.s[2] * z * z + w.s[3] * x * y + w.s[4] * x * z +
                         w.s[5] * y * z + dot(w.t, r);
    const float xx = x * x, yy = y * y, zz = z * z;
    const float order3 = x * (w.cubic[0] * xx + w.cubic[3] * x * y + w.cubic[4] * x * z + w.cubic[5] * yy +
                              w.cubic[7] * zz + w.cubic[9] * y * z) +
                         y * (w.cubic[1] * yy + w.cubic[6] * y * z + w.cubic[8] * zz) + z * (w.cubic[2] * zz);
    return order1 * inv_r3 + (order2 + order3 * inv_r2) * inv_r5;
}

// The winding number at a finite q: nodes whose center is farther than
// sqrt(beta2 * radius_squared) use their expansion, others are opened,
// leaves summed exactly (each triangle's solid angle times its weight:
// 1, or 1 / its reference count where a builder referenced it from several
// leaves). exact: every triangle summed.
RF_HDI float winding_number_query(const QueryView& view, const WindingNode* nodes, const float* slot_weights, Vec3f q,
                                  float beta2, bool exact) {
    if (view.node_count == 0) return 0.0f;
    uint32_t stack[kQueryStackSize];
    int size = 0;
    stack[size++] = 0;
    float sum = 0.0f;
    while (size > 0) {
        const uint32_t index = stack[--size];
        const WindingNode& w = nodes[index];
        const Vec3f r = w.center - q;
        const float r2 = dot(r, r);
        if (!exact && r2 > beta2 * w.radius_squared) {
            sum += expansion_times_four_pi(w, r, r2);
            continue;
        }
        const BvhNode& node = view.nodes[index];
        if (node.is_leaf()) {
            for (uint32_t s = node.first; s < node.first + node.count; ++s) {
                const SlotTriangle& slot = view.slots[s];
                if (slot.zero_area()) continue;
                const float omega = triangle_solid_angle(q, slot.tri);
                sum += slot_weights ? omega * slot_weights[s] : omega;
            }
        } else {
            RF_ASSERT(size + 2 <= kQueryStackSize, "a BVH deeper than kBvhMaxDepth");
            stack[size++] = node.first + 1;
            stack[size++] = node.first;
        }
    }
    return sum * kInvFourPi;
}

// The expansion of every node of `bvh` over `slots` (its triangles in slot
// order) into `nodes` (resized to the node count), in parallel over
// subtrees; `slot_weights` empty (every weight 1) or one per slot.
void compute_winding_nodes(const Bvh& bvh, std::span<const SlotTriangle> slots, std::span<const float> slot_weights,
                           std::vector<WindingNode>& nodes);

}  // namespace rf::query
