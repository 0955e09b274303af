// The BART AFF parser's shared state: what its parts (aff_*.cpp, one per
// concern) read into and assemble from. Internal to the AFF loader.
//
// AFF ("Animated File Format") is the scene format of BART, "A Benchmark for
// Animated Ray Tracing" (J. Lext, U. Assarsson, T. Möller, IEEE CG&A 2001); it
// extends Eric Haines's NFF 3.9 with meshes, textured and animated triangles,
// includes, static and keyframe-animated transform blocks. load_aff keeps the
// animation in Scene::animation (one node per transform block under or above
// an animated one, the tpa triangles as vertex keyframes, `k camera` as the
// camera's node) and evaluates it at the start of the animation (`a start end
// frames`), or 0 when the file has no `a` line; Scene::set_time moves it.
// load_aff_at_time gives a still scene at another time (the blocks evaluated
// here, hidden blocks left out), the reference the animated scene is tested against.
//
// Supported (see docs/scene-format.md for the mapping onto rf::Scene):
//   comments (# and %, to the end of the line), v (from/at/up/angle/hither/
//   resolution), b, l (point lights, world space), am (the ambient light:
//   fm materials' ambient color times it becomes Material::ambient, the
//   Whitted integrator's k_a * I_a), a, d (detail level), f and fm materials, p and pp polygons (fan-
//   triangulated), tt / ttp textured triangles, tpa animated triangles
//   (linear in time, clamped), m meshes, i includes (relative to the including
//   file; cycles and nesting deeper than 64 are errors; each occurrence is
//   expanded again), xs static transforms T*R*S, x animated transforms
//   evaluated from their k keyframes (Kochanek-Bartels splines for transl and
//   scale, squad of quaternions for rot, step visibility, as in BART's
//   reference code), k camera (animates the viewpoint), s spheres and c cones
//   (tessellated, counted in a note).
// Every problem in the input is an rf::Error "file:line: reason". Guards:
// counts are checked against what is left of the file before allocating,
// arrays against the memory budget, and the geometry of all expansions
// together too; at most 100,000 include expansions and 1 GiB of parsed text
// per load (a file that includes the next one twice, 30 deep, would be 2^30).
//
// Where the parts are:
//   aff_parser.cpp      entry points, files, includes, the statement loop
//   aff_tokens.*        tokens, numbers, counts (TokenReader)
//   aff_view_lights.cpp v, l, a
//   aff_materials.cpp   f, fm, textures
//   aff_triangles.cpp   p, pp, tt, ttp, tpa (loose triangles)
//   aff_primitives.cpp  s, c (tessellated)
//   aff_mesh.cpp        m
//   aff_transforms.cpp  xs, x, k
//   aff_keyframes.*     spline and quaternion evaluation
//   aff_assemble.cpp    the still rf::Scene at one time
//   aff_animation.cpp   the rf::Scene with its animation
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include "io/aff/aff_keyframes.h"
#include "io/aff/aff_tokens.h"
#include "rayforge/io/scene_io.h"

namespace rf::io::aff {

inline constexpr int kMaxIncludeDepth = 64;
inline constexpr size_t kMaxExpansions = 100'000;           // include expansions in one load
inline constexpr size_t kMaxParsedBytes = size_t(1) << 30;  // text parsed, includes counted each time
inline constexpr int kConeSegments = 16;                     // 32 triangles per cone
inline constexpr int kSphereStacks = 12, kSphereSlices = 24; // 528 triangles per sphere
inline constexpr double kPi = 3.14159265358979323846;

// "rayforge: warning: ..." and "rayforge: note: ..." lines on stderr.
void warn(const std::string& message);
void note(const std::string& message);

struct Node {  // a transform block; node 0 is the world
    int parent = -1;
    bool animated = false;
    Affine3f local = Affine3f::identity();
    std::string name;  // animated: the k name
    std::string file;
    long line = 0;
};

struct MaterialDef {  // an f or fm line
    Vec3f diffuse{0.8f, 0.8f, 0.8f}, specular{0, 0, 0};
    Vec3f ambient{0, 0, 0};  // fm only: k_a (scaled by the am light when the scene is assembled)
    float shine = 0, transmittance = 0, ior = 1.5f;
    bool operator<(const MaterialDef& o) const {
        auto key = [](const MaterialDef& m) {
            return std::make_tuple(m.diffuse.x, m.diffuse.y, m.diffuse.z, m.specular.x, m.specular.y, m.specular.z,
                                   m.ambient.x, m.ambient.y, m.ambient.z, m.shine, m.transmittance, m.ior);
        };
        return key(*this) < key(o);
    }
};

struct PendingMesh {  // a mesh and the transform block it is in
    Mesh mesh;
    int node = 0;
};

struct TriKey {  // tpa: one key of an animated triangle
    double t = 0;
    Vec3f p[3], n[3];
};

struct AnimatedTriangle {
    std::vector<TriKey> keys;
    uint32_t material = 0;
    size_t mesh = 0;  // pending_ index of the loose mesh it goes into
};

// An animated triangle's corners and raw (unnormalised) normals at time t:
// linear between the two keys around t, clamped.
void animated_triangle_at(const AnimatedTriangle& tri, double t, Vec3f p[3], Vec3f n[3]);

struct LightDef {
    Vec3f position, color;
};

struct ViewDef {
    Vec3f from{0, 0, 5}, at{0, 0, 0}, up{0, 1, 0};
    float angle = 45.0f;
    long line = 0;
};

// Reads a root file and its includes, then assembles the scene at one time.
class AffParser {
public:
    AffParser(std::string root, const LoadOptions& options);
    Scene load(std::optional<double> time);

private:
    struct FileState {  // the file being parsed
        TokenReader in;
        size_t block_base = 0;  // node stack size on entry
    };
    // World transform and visibility of every transform block at one time.
    struct BlockStates {
        std::vector<Affine3f> world;
        std::vector<char> visible;
        std::set<std::string> unanimated;  // x blocks without a k
    };

    TokenReader& in() { return file_->in; }
    [[nodiscard]] Error error(long line, const std::string& reason) const { return file_->in.error(line, reason); }

    // aff_parser.cpp: files, includes, statements
    std::string_view file_text(const std::string& path);
    void parse_file(const std::string& path, const std::string& canonical, int depth);
    void parse_statements(int depth);
    void parse_include(int depth, long line);

    // aff_view_lights.cpp
    void parse_view(long line);
    void parse_light();
    void parse_anim_params(long line);

    // aff_materials.cpp
    void set_material(const MaterialDef& def);
    void parse_nff_material();
    void parse_fm_material();
    // The scene material for the current definition and a texture ("" = none).
    uint32_t material_index(const std::string& texture_name);
    std::string find_texture(const std::string& name);
    void attach_textures(Scene& scene);

    // aff_triangles.cpp
    [[nodiscard]] int current_node() const { return node_stack_.empty() ? 0 : node_stack_.back(); }
    void account(size_t bytes);  // geometry of all expansions against the budget
    Mesh& loose_mesh();
    void add_triangle(const Vec3f p[3], const Vec3f* n, const Vec2f* uv, uint32_t material);
    void parse_polygon(bool with_normals);
    void parse_textured_triangle(bool with_normals);
    void parse_animated_triangle(long line);

    // aff_primitives.cpp
    void parse_sphere(long line);
    void parse_cone(long line);

    // aff_mesh.cpp
    void parse_mesh(long line);

    // aff_transforms.cpp
    void push_node(Node node);
    void parse_static_transform(long line);
    void parse_animated_transform(long line);
    void parse_keyframes(long line);

    // aff_assemble.cpp: the still scene at one time, and what both scenes share
    Scene assemble(double t);
    void add_materials_and_settings(Scene& scene);
    [[nodiscard]] BlockStates evaluate_blocks(double t) const;
    void add_animated_triangles(double t);
    void move_meshes(Scene& scene, const BlockStates& blocks);
    [[nodiscard]] Camera make_camera(double t) const;
    void add_lights(Scene& scene) const;
    void report(const std::set<std::string>& unanimated) const;

    // aff_animation.cpp: the scene with its animation (Scene::animation), evaluated at t
    Scene assemble_animated(double t);
    [[nodiscard]] std::vector<int32_t> add_nodes(rf::Animation& animation);  // accounts the keys it copies
    void place_meshes(Scene& scene, const BlockStates& blocks, const std::vector<int32_t>& node_of,
                      const std::vector<size_t>& static_vertices);
    void add_vertex_keyframes(Scene& scene, uint32_t mesh, size_t first_vertex, const std::vector<size_t>& triangles);
    void add_camera_animation(Scene& scene) const;
    void set_time_range(rf::Animation& animation) const;

    // Input and limits.
    std::string root_;
    LoadOptions options_;
    const std::string polygon_what_, geometry_what_;  // budget error prefixes
    FileState* file_ = nullptr;
    std::map<std::string, std::string> texts_;
    std::map<std::string, std::pair<std::string, std::string>> include_lookup_;  // -> (path, canonical)
    std::vector<std::string> include_stack_;
    size_t expansions_ = 0, parsed_bytes_ = 0, total_bytes_ = 0;
    int64_t detail_level_ = 0;

    // Transform blocks and animation.
    std::vector<Node> nodes_;
    std::vector<int> node_stack_;
    std::map<std::string, Animation> animations_;
    std::optional<double> anim_start_;
    double anim_end_ = 0.0;
    int64_t anim_frames_ = 1;

    // Materials and textures.
    std::map<MaterialDef, uint32_t> material_defs_;
    std::vector<MaterialDef> def_list_;
    int current_def_ = -1;
    std::vector<Material> materials_;
    std::vector<std::string> material_texture_;  // per material: resolved texture path or ""
    std::vector<Vec3f> fallback_color_;          // per material: base color without its texture
    std::map<std::pair<int, std::string>, uint32_t> material_index_;
    std::map<std::string, std::string> texture_lookup_;
    std::set<std::string> missing_textures_;

    // Geometry, lights, view.
    std::vector<PendingMesh> pending_;
    std::vector<AnimatedTriangle> animated_triangles_;
    std::unordered_map<int, size_t> loose_;  // node -> pending_ index of its loose mesh
    std::vector<LightDef> lights_;
    std::optional<ViewDef> view_;
    std::optional<std::pair<int, int>> resolution_;
    std::optional<Vec3f> background_;
    Vec3f ambient_light_{0.0f, 0.0f, 0.0f};  // the last am line (none: no ambient term)
    size_t skipped_polygons_ = 0, skipped_primitives_ = 0, spheres_ = 0, cones_ = 0;
};

}  // namespace rf::io::aff
