// AFF loose triangles: p and pp polygons (fan-triangulated), tt and ttp
// textured triangles, tpa animated triangles (kept until the time is known).
// The loose triangles of one transform block share one mesh.
#include <cmath>
#include <filesystem>
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"

namespace rf::io::aff {

namespace fs = std::filesystem;

void AffParser::account(size_t bytes) {
    total_bytes_ += bytes;
    checked_array_bytes(geometry_what_, total_bytes_, 1);
}

// Loose triangles (p, pp, tt, ttp, tpa, s, c) of one transform block share a mesh.
Mesh& AffParser::loose_mesh() {
    const int node = current_node();
    auto it = loose_.find(node);
    if (it == loose_.end()) {
        PendingMesh pending;
        pending.node = node;
        pending.mesh.name = fs::path(in().path()).stem().string() + "#polygons" + std::to_string(pending_.size());
        budgeted_push_back(pending_, std::move(pending), root_ + ": AFF mesh array");
        it = loose_.emplace(node, pending_.size() - 1).first;
    }
    return pending_[it->second].mesh;
}

// Unit normals: the given ones (n) where they are usable, else the face normal.
void AffParser::add_triangle(const Vec3f p[3], const Vec3f* n, const Vec2f* uv, uint32_t material) {
    Mesh& mesh = loose_mesh();
    const std::string& what = polygon_what_;
    Vec3f normals[3];
    const Vec3f face = cross(p[1] - p[0], p[2] - p[0]);
    const float face_len = length(face);
    const Vec3f face_n = face_len > 0.0f ? face / face_len : Vec3f{0, 0, 1};
    for (int c = 0; c < 3; ++c) {
        Vec3f v = n ? n[c] : face_n;
        const float len = length(v);
        normals[c] = (len > 0.0f && std::isfinite(len)) ? v / len : face_n;
    }
    const uint32_t base = checked_index_count(what, uint64_t(mesh.positions.size()) + 3) - 3;
    for (int c = 0; c < 3; ++c) {
        budgeted_push_back(mesh.positions, p[c], what);
        budgeted_push_back(mesh.normals, normals[c], what);
        budgeted_push_back(mesh.uvs, uv ? uv[c] : Vec2f{0, 0}, what);
        budgeted_push_back(mesh.indices, base + uint32_t(c), what);
    }
    budgeted_push_back(mesh.material_ids, material, what);
    account(3 * (2 * sizeof(Vec3f) + sizeof(Vec2f) + sizeof(uint32_t)) + sizeof(uint32_t));
}

// p N x y z ... / pp N x y z nx ny nz ...; fewer than 3 vertices are skipped (counted in a warning).
void AffParser::parse_polygon(bool with_normals) {
    const size_t n = in().read_count(with_normals ? "polygon patch vertex count" : "polygon vertex count", with_normals ? 6 : 3);
    std::vector<Vec3f> points, normals;
    budgeted_reserve(points, n, root_ + ": AFF polygon");
    if (with_normals) budgeted_reserve(normals, n, root_ + ": AFF polygon");
    for (size_t i = 0; i < n; ++i) {
        points.push_back(in().read_vec3("polygon vertex"));
        if (with_normals) normals.push_back(in().read_vec3("polygon normal"));
    }
    if (n < 3) {
        ++skipped_polygons_;
        return;
    }
    const uint32_t material = material_index("");
    for (size_t k = 2; k < n; ++k) {  // fan: NFF polygons are planar and convex
        const Vec3f p[3] = {points[0], points[k - 1], points[k]};
        if (with_normals) {
            const Vec3f nn[3] = {normals[0], normals[k - 1], normals[k]};
            add_triangle(p, nn, nullptr, material);
        } else {
            add_triangle(p, nullptr, nullptr, material);
        }
    }
}

// tt texture (x y z u v) x3 / ttp texture (x y z nx ny nz u v) x3
void AffParser::parse_textured_triangle(bool with_normals) {
    const std::string texture = in().read_word("texture name");
    Vec3f p[3], n[3];
    Vec2f uv[3];
    for (int c = 0; c < 3; ++c) {
        p[c] = in().read_vec3("textured triangle vertex");
        if (with_normals) n[c] = in().read_vec3("textured triangle normal");
        const float u = in().read_float("texture coordinate");
        const float v = in().read_float("texture coordinate");
        uv[c] = Vec2f{u, v};
    }
    add_triangle(p, with_normals ? n : nullptr, uv, material_index(texture));
}

// tpa: keyframed triangle; linear between the two keys around the time, clamped.
void AffParser::parse_animated_triangle(long line) {
    const size_t keys = in().read_count("animated triangle key count", 19);
    if (keys < 1) throw error(line, "animated triangle needs at least one key");
    std::vector<TriKey> k;
    budgeted_reserve(k, keys, root_ + ": AFF animated triangle");
    for (size_t i = 0; i < keys; ++i) {
        TriKey key;
        key.t = in().read_float("animated triangle time");
        for (int c = 0; c < 3; ++c) {
            key.p[c] = in().read_vec3("animated triangle vertex");
            key.n[c] = in().read_vec3("animated triangle normal");
        }
        k.push_back(key);
    }
    account(keys * sizeof(TriKey));
    // Evaluated at the end, once the time is known; it goes into this block's loose mesh.
    AnimatedTriangle tri;
    tri.keys = std::move(k);
    tri.material = material_index("");
    (void)loose_mesh();
    tri.mesh = loose_.at(current_node());
    budgeted_push_back(animated_triangles_, std::move(tri), root_ + ": AFF animated triangle array");
}

}  // namespace rf::io::aff
