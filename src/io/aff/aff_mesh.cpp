// The AFF `m` directive: an indexed mesh whose triangles index vertices,
// normals and texture coordinates separately; each distinct (vertex, normal,
// texcoord) triple becomes one vertex of the rf::Mesh.
//
//   m vertices N x y z ... [normals N ...] [texturecoords N texture u v ...]
//     triangles N (v v v [n n n] [t t t]) ...
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"

namespace rf::io::aff {

namespace {

namespace fs = std::filesystem;

constexpr uint32_t kAbsent = 0xFFFFFFFFu;

// The arrays of an `m` directive as written, before its triangles.
struct MeshArrays {
    std::vector<Vec3f> vertices, normals;
    std::vector<Vec2f> uvs;
    std::string texture_name;
    bool has_normals = false, has_uvs = false;
};

// A triangle corner's indices into MeshArrays (kAbsent: not given).
struct Corner {
    uint32_t v, n, t;
};

// From `vertices` through the word `triangles`.
MeshArrays read_mesh_arrays(TokenReader& in, const std::string& where) {
    MeshArrays a;
    const size_t nv = in.read_count("mesh vertex count", 3);
    budgeted_reserve(a.vertices, nv, where + " vertex array");
    for (size_t i = 0; i < nv; ++i) a.vertices.push_back(in.read_vec3("mesh vertex"));
    Token t = in.expect_token("'normals', 'texturecoords' or 'triangles'");
    if (t.text == "normals") {
        a.has_normals = true;
        const size_t nn = in.read_count("mesh normal count", 3);
        budgeted_reserve(a.normals, nn, where + " normal array");
        for (size_t i = 0; i < nn; ++i) a.normals.push_back(in.read_vec3("mesh normal"));
        t = in.expect_token("'texturecoords' or 'triangles'");
    }
    if (t.text == "texturecoords") {
        a.has_uvs = true;
        const size_t nt = in.read_count("mesh texture coordinate count", 2);
        a.texture_name = in.read_word("mesh texture name");
        budgeted_reserve(a.uvs, nt, where + " texture coordinate array");
        for (size_t i = 0; i < nt; ++i) {
            const float u = in.read_float("mesh texture coordinate");
            const float v = in.read_float("mesh texture coordinate");
            a.uvs.push_back(Vec2f{u, v});
        }
        t = in.expect_token("'triangles'");
    }
    if (t.text != "triangles") throw in.error(t.line, "mesh: expected 'triangles', found '" + std::string(t.text.substr(0, 24)) + "'");
    return a;
}

// Reads `triangles` triangles into mesh.indices and returns the distinct
// corners, in order of first use; the variants of a position are chained.
std::vector<Corner> read_mesh_triangles(TokenReader& in, const MeshArrays& a, size_t triangles, Mesh& mesh,
                                        const std::string& where) {
    std::vector<uint32_t> first_variant(a.vertices.size(), kAbsent), next_variant;
    std::vector<Corner> corners;
    budgeted_resize(mesh.indices, triangles * 3, where + " index array");
    for (size_t tri = 0; tri < triangles; ++tri) {
        Corner c[3];
        for (auto& corner : c) corner = {in.read_index("mesh vertex", a.vertices.size()), kAbsent, kAbsent};
        if (a.has_normals) for (auto& corner : c) corner.n = in.read_index("mesh normal", a.normals.size());
        if (a.has_uvs) for (auto& corner : c) corner.t = in.read_index("mesh texture coordinate", a.uvs.size());
        for (int k = 0; k < 3; ++k) {
            uint32_t found = first_variant[c[k].v];
            while (found != kAbsent && (corners[found].n != c[k].n || corners[found].t != c[k].t)) found = next_variant[found];
            if (found == kAbsent) {
                found = uint32_t(corners.size());
                budgeted_push_back(corners, c[k], where + " vertex array");
                budgeted_push_back(next_variant, first_variant[c[k].v], where + " vertex array");
                first_variant[c[k].v] = found;
            }
            mesh.indices[tri * 3 + size_t(k)] = found;
        }
    }
    return corners;
}

// The given normals, unit length; zero ones get the normals computed from the triangles.
void set_given_normals(const MeshArrays& a, const std::vector<Corner>& corners, Mesh& mesh, const std::string& where) {
    const size_t n = corners.size();
    budgeted_resize(mesh.normals, n, where + " normal array");
    bool any_zero = false;
    for (size_t i = 0; i < n; ++i) {
        const Vec3f v = a.normals[corners[i].n];
        const float len = length(v);
        if (len > 0.0f && std::isfinite(len)) mesh.normals[i] = v / len;
        else any_zero = true;
    }
    if (!any_zero) return;
    Mesh computed;
    computed.positions = mesh.positions;
    computed.indices = mesh.indices;
    computed.compute_vertex_normals();
    for (size_t i = 0; i < n; ++i) {
        const Vec3f v = a.normals[corners[i].n];
        if (!(length(v) > 0.0f)) mesh.normals[i] = computed.normals[i];
    }
}

// Positions, texture coordinates and normals of the distinct corners.
void set_vertices(const MeshArrays& a, const std::vector<Corner>& corners, Mesh& mesh, const std::string& where,
                  bool compute_missing_normals) {
    const size_t n = corners.size();
    budgeted_resize(mesh.positions, n, where + " vertex array");
    for (size_t i = 0; i < n; ++i) mesh.positions[i] = a.vertices[corners[i].v];
    if (a.has_uvs) {
        budgeted_resize(mesh.uvs, n, where + " texture coordinate array");
        for (size_t i = 0; i < n; ++i) mesh.uvs[i] = a.uvs[corners[i].t];
    }
    if (a.has_normals) set_given_normals(a, corners, mesh, where);
    else if (compute_missing_normals) mesh.compute_vertex_normals();
}

}  // namespace

void AffParser::parse_mesh(long line) {
    Token t = in().expect_token("'vertices'");
    if (t.text != "vertices") throw error(t.line, "mesh: expected 'vertices', found '" + std::string(t.text.substr(0, 24)) + "'");
    const std::string where = root_ + ": AFF mesh";
    const MeshArrays arrays = read_mesh_arrays(in(), where);
    const size_t per_triangle = 3 + (arrays.has_normals ? 3 : 0) + (arrays.has_uvs ? 3 : 0);
    const size_t nt = in().read_count("mesh triangle count", per_triangle);
    checked_index_count(where + " triangle count", uint64_t(nt) * 3);

    Mesh mesh;
    const std::vector<Corner> corners = read_mesh_triangles(in(), arrays, nt, mesh, where);
    set_vertices(arrays, corners, mesh, where, options_.compute_missing_normals && nt > 0);
    if (nt == 0) return;  // an empty mesh adds nothing
    budgeted_resize(mesh.material_ids, nt, where + " material array");
    std::fill(mesh.material_ids.begin(), mesh.material_ids.end(), material_index(arrays.texture_name));
    mesh.name = fs::path(in().path()).stem().string() + ":" + std::to_string(line);
    account(mesh.memory_bytes());
    PendingMesh pending;
    pending.mesh = std::move(mesh);
    pending.node = current_node();
    budgeted_push_back(pending_, std::move(pending), root_ + ": AFF mesh array");
}

}  // namespace rf::io::aff
