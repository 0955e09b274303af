// A triangle mesh in its own object space.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "rayforge/math/box.h"
#include "rayforge/math/vec.h"

namespace rf {

struct Mesh {
    std::string name;
    std::vector<Vec3f> positions;
    std::vector<Vec3f> normals;    // empty, or one per position
    std::vector<Vec2f> uvs;        // empty, or one per position
    std::vector<Vec4f> tangents;   // empty, or one per position (xyz, w = handedness)
    std::vector<uint32_t> indices; // 3 per triangle, 32-bit
    std::vector<uint32_t> material_ids;  // one per triangle (index into Scene::materials)

    [[nodiscard]] size_t triangle_count() const { return indices.size() / 3; }
    [[nodiscard]] size_t vertex_count() const { return positions.size(); }
    [[nodiscard]] Box3f bounds() const;
    [[nodiscard]] size_t memory_bytes() const;
    // Area-weighted vertex normals (for meshes loaded without normals).
    void compute_vertex_normals();
    // Checks sizes, index ranges and finite coordinates; throws rf::Error
    // naming the mesh and the first problem found.
    void validate() const;
};

}  // namespace rf
