#include "ooc/quad_pairing.h"

#include "core/parallel.h"

#include <algorithm>

namespace rf::pack {

namespace {

constexpr uint32_t kNone = QuadRef::kNoTriangle;

struct EdgeUse {
    uint64_t key;       // the edge's two vertices, smaller first
    uint32_t tri_edge;  // 3 * triangle + edge (edge e runs from corner e to corner e + 1)
    bool operator<(const EdgeUse& o) const { return key < o.key || (key == o.key && tri_edge < o.tri_edge); }
};

// neighbour[3 t + e]: the triangle across edge e of t with the same material, or kNone.
std::vector<uint32_t> find_neighbours(std::span<const uint32_t> indices, std::span<const uint32_t> material) {
    const size_t n = indices.size() / 3;
    std::vector<EdgeUse> uses(3 * n);
    for (size_t t = 0; t < n; ++t)
        for (uint32_t e = 0; e < 3; ++e) {
            const uint32_t a = indices[3 * t + e], b = indices[3 * t + (e + 1) % 3];
            uses[3 * t + e] = {uint64_t(std::min(a, b)) << 32 | std::max(a, b), uint32_t(3 * t + e)};
        }
    parallel::sort(uses, std::less<EdgeUse>());
    std::vector<uint32_t> neighbour(3 * n, kNone);
    for (size_t i = 0; i + 1 < uses.size();) {
        size_t j = i + 1;
        while (j < uses.size() && uses[j].key == uses[i].key) ++j;
        // Only a manifold edge (two uses) pairs; a degenerate edge (a == b) never does.
        const uint32_t a = uint32_t(uses[i].key >> 32), b = uint32_t(uses[i].key);
        if (j - i == 2 && a != b) {
            const uint32_t t0 = uses[i].tri_edge / 3, t1 = uses[i + 1].tri_edge / 3;
            if (t0 != t1 && material[t0] == material[t1]) {
                neighbour[uses[i].tri_edge] = t1;
                neighbour[uses[i + 1].tri_edge] = t0;
            }
        }
        i = j;
    }
    return neighbour;
}

float perimeter(std::span<const Vec3f> p, const uint32_t* tri) {
    return length(p[tri[1]] - p[tri[0]]) + length(p[tri[2]] - p[tri[1]]) + length(p[tri[0]] - p[tri[2]]);
}

// The quad of triangle t alone.
QuadRef single(std::span<const uint32_t> indices, uint32_t t) {
    QuadRef q;
    q.v[0] = indices[3 * t];
    q.v[1] = indices[3 * t + 1];
    q.v[2] = indices[3 * t + 2];
    q.v[3] = q.v[0];
    q.first = t;
    return q;
}

// The quad of a (across its edge e) and b: a rotated so that edge e runs
// from corner 2 to corner 0, then b's third vertex.
QuadRef paired(std::span<const uint32_t> indices, uint32_t a, uint32_t e, uint32_t b) {
    QuadRef q;
    q.first = a;
    q.second = b;
    for (int k = 0; k < 3; ++k) {
        const uint8_t corner = uint8_t((e + 1 + k) % 3);
        q.corner_of[0][k] = corner;
        q.v[k] = indices[3 * a + corner];
    }
    const uint32_t* tb = &indices[3 * b];
    const uint32_t want[3] = {q.v[0], q.v[2], kNone};
    uint8_t third = 0;
    for (uint8_t c = 0; c < 3; ++c)
        if (tb[c] != q.v[0] && tb[c] != q.v[2]) third = c;
    q.v[3] = tb[third];
    for (int k = 0; k < 2; ++k)
        for (uint8_t c = 0; c < 3; ++c)
            if (tb[c] == want[k]) q.corner_of[1][k] = c;
    q.corner_of[1][2] = third;
    return q;
}

}  // namespace

std::vector<QuadRef> pair_triangles(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                                    std::span<const uint32_t> material) {
    const size_t n = indices.size() / 3;
    const std::vector<uint32_t> neighbour = find_neighbours(indices, material);
    std::vector<uint8_t> taken(n, 0);
    std::vector<QuadRef> quads;
    quads.reserve(n / 2 + n / 8 + 1);
    for (uint32_t t = 0; t < n; ++t) {
        if (taken[t]) continue;
        taken[t] = 1;
        uint32_t best_edge = kNone, best = kNone;
        float best_perimeter = 0.0f;
        const float own = perimeter(positions, &indices[3 * size_t(t)]);
        for (uint32_t e = 0; e < 3; ++e) {
            const uint32_t other = neighbour[3 * size_t(t) + e];
            if (other == kNone || taken[other]) continue;
            const uint32_t a = indices[3 * size_t(t) + e], b = indices[3 * size_t(t) + (e + 1) % 3];
            const float quad = own + perimeter(positions, &indices[3 * size_t(other)]) -
                               2.0f * length(positions[b] - positions[a]);
            if (best == kNone || quad < best_perimeter) {
                best = other;
                best_edge = e;
                best_perimeter = quad;
            }
        }
        if (best == kNone) {
            quads.push_back(single(indices, t));
        } else {
            taken[best] = 1;
            quads.push_back(paired(indices, t, best_edge, best));
        }
    }
    return quads;
}

}  // namespace rf::pack
