#include "rayforge/scene/mesh.h"

#include <cmath>
#include <string>

#include "rayforge/core/error.h"

namespace rf {

Box3f Mesh::bounds() const {
    Box3f b;
    for (const Vec3f& p : positions) b.extend(p);
    return b;
}

size_t Mesh::memory_bytes() const {
    return positions.size() * sizeof(Vec3f) + normals.size() * sizeof(Vec3f) + uvs.size() * sizeof(Vec2f) +
           tangents.size() * sizeof(Vec4f) + indices.size() * sizeof(uint32_t) +
           material_ids.size() * sizeof(uint32_t);
}

void Mesh::compute_vertex_normals() {
    // Area weighting falls out of the unnormalised cross product.
    normals.assign(positions.size(), Vec3f{0, 0, 0});
    const size_t n = positions.size();
    for (size_t t = 0; t + 2 < indices.size(); t += 3) {
        uint32_t i0 = indices[t], i1 = indices[t + 1], i2 = indices[t + 2];
        if (i0 >= n || i1 >= n || i2 >= n) continue;  // validate() reports these
        Vec3f face = cross(positions[i1] - positions[i0], positions[i2] - positions[i0]);
        if (!is_finite(face)) continue;
        normals[i0] += face;
        normals[i1] += face;
        normals[i2] += face;
    }
    for (Vec3f& nrm : normals) {
        float len = length(nrm);
        nrm = len > 0.0f && std::isfinite(len) ? nrm / len : Vec3f{0, 0, 1};
    }
}

void Mesh::validate() const {
    const std::string who = "mesh '" + name + "'";
    if (indices.size() % 3 != 0)
        throw Error(who + ": index count " + std::to_string(indices.size()) + " is not a multiple of 3");
    if (positions.size() > 0xFFFFFFFFull)
        throw Error(who + ": " + std::to_string(positions.size()) + " vertices exceed 32-bit indices");
    if (!normals.empty() && normals.size() != positions.size())
        throw Error(who + ": " + std::to_string(normals.size()) + " normals for " + std::to_string(positions.size()) + " vertices");
    if (!uvs.empty() && uvs.size() != positions.size())
        throw Error(who + ": " + std::to_string(uvs.size()) + " uvs for " + std::to_string(positions.size()) + " vertices");
    if (!tangents.empty() && tangents.size() != positions.size())
        throw Error(who + ": " + std::to_string(tangents.size()) + " tangents for " + std::to_string(positions.size()) + " vertices");
    if (material_ids.size() != triangle_count())
        throw Error(who + ": " + std::to_string(material_ids.size()) + " material ids for " +
                    std::to_string(triangle_count()) + " triangles");
    for (size_t i = 0; i < positions.size(); ++i)
        if (!is_finite(positions[i]))
            throw Error(who + ": vertex " + std::to_string(i) + " has a non-finite coordinate");
    for (size_t i = 0; i < indices.size(); ++i)
        if (indices[i] >= positions.size())
            throw Error(who + ": triangle " + std::to_string(i / 3) + " references vertex " +
                        std::to_string(indices[i]) + " of " + std::to_string(positions.size()));
}

}  // namespace rf
