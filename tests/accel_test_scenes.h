// Procedural geometry for the intersection, BVH build and traversal tests:
// closed meshes with shared vertices (for watertightness), triangle soups and
// nasty cases, built straight into SceneGeometry (no loaders involved).
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::test {

struct IndexedMesh {
    std::vector<Vec3f> positions;
    std::vector<uint32_t> indices;  // 3 per triangle, consistently wound
};

// Icosahedron subdivided `levels` times, vertices on the unit sphere. Edge
// midpoints are shared, so neighbouring triangles use bit-identical vertices.
inline IndexedMesh make_icosphere(int levels) {
    const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
    IndexedMesh m;
    for (Vec3f p : {Vec3f(-1, t, 0), Vec3f(1, t, 0), Vec3f(-1, -t, 0), Vec3f(1, -t, 0), Vec3f(0, -1, t),
                    Vec3f(0, 1, t), Vec3f(0, -1, -t), Vec3f(0, 1, -t), Vec3f(t, 0, -1), Vec3f(t, 0, 1),
                    Vec3f(-t, 0, -1), Vec3f(-t, 0, 1)}) {
        m.positions.push_back(normalize(p));
    }
    m.indices = {0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8,
                 3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1};
    for (int level = 0; level < levels; ++level) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints;
        auto midpoint = [&](uint32_t a, uint32_t b) {
            const auto key = std::minmax(a, b);
            auto it = midpoints.find(key);
            if (it != midpoints.end()) return it->second;
            m.positions.push_back(normalize((m.positions[a] + m.positions[b]) * 0.5f));
            const auto index = static_cast<uint32_t>(m.positions.size() - 1);
            midpoints.emplace(key, index);
            return index;
        };
        std::vector<uint32_t> next;
        for (size_t i = 0; i < m.indices.size(); i += 3) {
            const uint32_t a = m.indices[i], b = m.indices[i + 1], c = m.indices[i + 2];
            const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
            next.insert(next.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
        }
        m.indices = std::move(next);
    }
    return m;
}

// Surface of the cube [-1, 1]^3, each face an n x n grid of quads (two
// triangles each); vertices on cube edges and corners are shared by faces.
inline IndexedMesh make_tessellated_cube(int n) {
    IndexedMesh m;
    std::map<std::tuple<int, int, int>, uint32_t> vertex_of;
    auto vertex = [&](int i, int j, int k) {
        const auto key = std::make_tuple(i, j, k);
        auto it = vertex_of.find(key);
        if (it != vertex_of.end()) return it->second;
        const float s = 2.0f / static_cast<float>(n);
        m.positions.emplace_back(-1.0f + s * i, -1.0f + s * j, -1.0f + s * k);
        const auto index = static_cast<uint32_t>(m.positions.size() - 1);
        vertex_of.emplace(key, index);
        return index;
    };
    // Each face: fixed axis at 0 or n, the other two axes over the grid.
    for (int axis = 0; axis < 3; ++axis) {
        for (int side : {0, n}) {
            for (int a = 0; a < n; ++a) {
                for (int b = 0; b < n; ++b) {
                    auto grid = [&](int da, int db) {
                        int c[3];
                        c[axis] = side;
                        c[(axis + 1) % 3] = a + da;
                        c[(axis + 2) % 3] = b + db;
                        return vertex(c[0], c[1], c[2]);
                    };
                    const uint32_t v00 = grid(0, 0), v10 = grid(1, 0), v01 = grid(0, 1), v11 = grid(1, 1);
                    if (side == n) {
                        m.indices.insert(m.indices.end(), {v00, v10, v11, v00, v11, v01});
                    } else {
                        m.indices.insert(m.indices.end(), {v00, v11, v10, v00, v01, v11});
                    }
                }
            }
        }
    }
    return m;
}

inline void append(SceneGeometry& geometry, const Triangle& tri) {
    geometry.triangle_instance.push_back(0);
    geometry.local_triangle.push_back(static_cast<uint32_t>(geometry.triangles.size()));
    geometry.material.push_back(0);
    geometry.triangles.push_back(tri);
    geometry.bounds.extend(tri.bounds());
}

// An rf::Mesh of `m`, every triangle on material 0 (scenes built by hand in tests).
inline Mesh to_mesh(const IndexedMesh& m, const std::string& name) {
    Mesh mesh;
    mesh.name = name;
    mesh.positions = m.positions;
    mesh.indices = m.indices;
    mesh.material_ids.assign(m.indices.size() / 3, 0);
    return mesh;
}

inline SceneGeometry to_geometry(const IndexedMesh& mesh, float scale = 1.0f, Vec3f offset = Vec3f(0.0f)) {
    SceneGeometry g;
    for (size_t i = 0; i < mesh.indices.size(); i += 3) {
        append(g, {mesh.positions[mesh.indices[i]] * scale + offset, mesh.positions[mesh.indices[i + 1]] * scale + offset,
                   mesh.positions[mesh.indices[i + 2]] * scale + offset});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

inline Vec3f random_in_box(std::mt19937& rng, const Box3f& box) {
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    return {box.lo.x + u(rng) * (box.hi.x - box.lo.x), box.lo.y + u(rng) * (box.hi.y - box.lo.y),
            box.lo.z + u(rng) * (box.hi.z - box.lo.z)};
}

inline Vec3f random_direction(std::mt19937& rng) {
    std::normal_distribution<float> n(0.0f, 1.0f);
    for (;;) {
        const Vec3f d(n(rng), n(rng), n(rng));
        if (length_squared(d) > 1e-6f) return normalize(d);
    }
}

// `count` triangles with vertices spread `size` around centres in `box`.
inline SceneGeometry make_triangle_soup(size_t count, uint32_t seed, const Box3f& box, float size) {
    std::mt19937 rng(seed);
    SceneGeometry g;
    for (size_t i = 0; i < count; ++i) {
        const Vec3f c = random_in_box(rng, box);
        append(g, {c + random_direction(rng) * size, c + random_direction(rng) * size, c + random_direction(rng) * size});
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

// Cases a builder and a traversal must survive: zero-area triangles (repeated
// vertices, collinear, points), exact duplicates, axis-aligned flat
// triangles, very thin slivers.
inline SceneGeometry make_nasty_geometry(uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-4.0f, 4.0f);
    SceneGeometry g;
    for (int i = 0; i < 300; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
        switch (i % 6) {
            case 0: append(g, {a, a, a}); break;                                   // a point
            case 1: append(g, {a, b, a * 0.5f + b * 0.5f}); break;                 // collinear
            case 2: append(g, {a, b, c}); append(g, {a, b, c}); break;             // duplicates
            case 3: append(g, {a, Vec3f(b.x, a.y, b.z), Vec3f(c.x, a.y, c.z)}); break;  // flat in y
            case 4: append(g, {a, a + Vec3f(3.0f, 0.0f, 1e-5f), a + Vec3f(0.0f, 1e-6f, 0.0f)}); break;  // sliver
            case 5: append(g, {Vec3f(a.x, 0.0f, a.z), Vec3f(b.x, 0.0f, b.z), Vec3f(c.x, 0.0f, c.z)}); break;  // shared plane y=0
        }
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return g;
}

// Point triangles whose 63-bit Morton codes are 1^i 0 0..0 for i = 0..62,
// plus `duplicates` at the all-ones code: a Karras tree over them is a chain
// of 63 levels with a balanced tree of the duplicates hanging below, deeper
// than kBvhMaxDepth. A point at (2^21, 2^21, 2^21) fixes the centroid bounds
// to [0, 2^21]^3, so that the grid cells are exactly the unit cells.
inline SceneGeometry make_morton_chain(int duplicates) {
    SceneGeometry g;
    auto add_code = [&](uint64_t code) {
        float cell[3] = {0, 0, 0};
        for (int axis = 0; axis < 3; ++axis) {
            uint32_t v = 0;
            for (int k = 0; k < 21; ++k) v |= static_cast<uint32_t>((code >> (3 * k + 2 - axis)) & 1u) << k;
            cell[axis] = static_cast<float>(v) + 0.5f;
        }
        const Vec3f p(cell[0], cell[1], cell[2]);
        append(g, {p, p, p});
    };
    const uint64_t all_ones = (uint64_t{1} << 63) - 1;
    for (int i = 0; i < 63; ++i) add_code(i == 0 ? 0 : (all_ones >> (63 - i)) << (63 - i));
    for (int i = 0; i < duplicates; ++i) add_code(all_ones);
    const Vec3f corner(static_cast<float>(1u << 21));
    append(g, {corner, corner, corner});
    return g;
}

}  // namespace rf::test
