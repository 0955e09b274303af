// Procedural animated scenes: analogues of the UNC dynamic benchmarks that
// Garanzha 2014 measures its BVH update (ch. 2) and cluster builds (ch. 3) on
// (Exploding Dragon 252K, Cloth on ball 92K, Colliding N bodies 146K
// triangles; 3.33 s, 100 frames). No Stanford models, no downloads.
//
// explode: a rock (a cube-mapped sphere, welded at the seams, displaced
//   radially by fBm value noise, so it never intersects itself) cut into a few
//   hundred fragments by a multi-source Dijkstra over the triangle dual graph
//   (edge weights = centroid distance times noise, so the cracks are jagged);
//   every fragment is grown through shared edges, hence connected. Each
//   fragment is one mesh instanced once; its node flies ballistically and
//   spins after frame 15, bouncing on the ground (its lowest vertex).
// cloth: a position-based dynamics cloth (Müller et al. 2007: structural,
//   shear and bend distance constraints, gravity, sphere and ground
//   collisions, 16 substeps per frame) simulated on a grid of at most 48 x 48
//   particles, upsampled per frame to the rendered grid by Catmull-Rom
//   (linear extrapolation at the borders) and pushed out of the ball and
//   above the ground; stored as Linear VertexKeyframes of the rendered mesh.
// nbody: spheres of varied radius (bounding spheres of four shapes: sphere,
//   rock, rounded box, torus) bursting from one lattice-packed heap inside a
//   box; a rigid-body step with sequential impulses (restitution, Coulomb
//   friction that spins the bodies) and positional projection, sweep-and-prune
//   on x; stored as Linear translation + rotation keys per frame.
//
// Data layout: frame k's keys are at k / 30 s (k = 0 .. 99), so Animation::end
// = 3.3 s; the instances and meshes hold frame 0. Parallelism: the fragments'
// flights and the cloth's per-frame upsampling run on parallel.h; the cloth
// and n-body simulations are sequential (Gauss-Seidel). Determinism: every
// random choice is an integer hash of the seed (never std:: distributions),
// parallel work writes disjoint outputs, so a seed gives the same scene on any
// thread count; only libm rounding can differ between platforms.
#include "io/animated_scenes.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <limits>
#include <queue>
#include <tuple>
#include <unordered_map>
#include <utility>

#include "core/parallel.h"
#include "io/scene_building.h"
#include "math/random.h"
#include "scene/animation_eval.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kGravity = 9.81f;

float frame_time(int frame) { return float(frame) / kAnimatedSceneFps; }

// Uniform numbers from (seed, stream): the n-th is a hash of (key, n).
class HashRng {
public:
    HashRng(uint32_t seed, uint32_t stream) : key_(pcg_hash(seed ^ pcg_hash(stream ^ 0x2545f491u))) {}
    float next() { return hash_to_unit_float(pcg_hash(key_ ^ pcg_hash(counter_++))); }
    float range(float lo, float hi) { return lo + (hi - lo) * next(); }
    Vec3f unit_vector() {
        const float z = range(-1.0f, 1.0f), phi = range(0.0f, 2.0f * kPi);
        const float r = std::sqrt(std::fmax(0.0f, 1.0f - z * z));
        return {r * std::cos(phi), r * std::sin(phi), z};
    }

private:
    uint32_t key_;
    uint32_t counter_ = 0;
};

// 3D value noise in [0, 1): hashed lattice values, smoothstep-interpolated.
float value_noise3(Vec3f p, uint32_t seed) {
    const float fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
    const auto ix = uint32_t(int32_t(fx)), iy = uint32_t(int32_t(fy)), iz = uint32_t(int32_t(fz));
    auto smooth = [](float t) { return t * t * (3.0f - 2.0f * t); };
    const float tx = smooth(p.x - fx), ty = smooth(p.y - fy), tz = smooth(p.z - fz);
    auto lattice = [&](uint32_t dx, uint32_t dy, uint32_t dz) {
        return hash_to_unit_float(pcg_hash((ix + dx) ^ pcg_hash((iy + dy) ^ pcg_hash((iz + dz) ^ pcg_hash(seed)))));
    };
    float plane[2];
    for (uint32_t dz = 0; dz < 2; ++dz) {
        const float a = lattice(0, 0, dz) + (lattice(1, 0, dz) - lattice(0, 0, dz)) * tx;
        const float b = lattice(0, 1, dz) + (lattice(1, 1, dz) - lattice(0, 1, dz)) * tx;
        plane[dz] = a + (b - a) * ty;
    }
    return plane[0] + (plane[1] - plane[0]) * tz;
}

// Octaves of value noise, each of twice the frequency and half the amplitude.
float fbm3(Vec3f p, uint32_t seed, int octaves) {
    float sum = 0.0f, amplitude = 0.5f, total = 0.0f;
    for (int octave = 0; octave < octaves; ++octave) {
        sum += amplitude * value_noise3(p, seed + uint32_t(octave));
        total += amplitude;
        amplitude *= 0.5f;
        p = p * 2.0f;
    }
    return sum / total;
}

// --- quaternions (x, y, z, w), as Animation's rotation tracks hold them ---

Vec4f quat_axis_angle(Vec3f axis, float angle) {
    const float s = std::sin(0.5f * angle);
    return {axis.x * s, axis.y * s, axis.z * s, std::cos(0.5f * angle)};
}

Vec4f quat_mul(Vec4f a, Vec4f b) {
    return {a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
            a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w, a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z};
}

Vec4f quat_normalize(Vec4f q) {
    const float s = 1.0f / std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
    return {q.x * s, q.y * s, q.z * s, q.w * s};
}

// q turned by angular velocity w for dt (exact for a constant w).
Vec4f quat_spin(Vec4f q, Vec3f w, float dt) {
    const float speed = length(w);
    if (speed * dt < 1e-7f) return q;
    return quat_normalize(quat_mul(quat_axis_angle(w / speed, speed * dt), q));
}

// The rotation of unit quaternion q, as Scene::set_time evaluates it.
Affine3f quat_to_affine(Vec4f q) {
    const float xyzw[4] = {q.x, q.y, q.z, q.w};
    return quaternion_matrix(xyzw);
}

// --- scene pieces ---

Material diffuse(const std::string& name, Vec3f color, float roughness = 1.0f) {
    Material m;
    m.name = name;
    m.base_color = color;
    m.roughness = roughness;
    m.specular = roughness < 1.0f ? 0.5f : 0.0f;
    return m;
}

using io::add_material;
using io::add_mesh;
using io::add_sun_and_sky;

// A square of half-size `half` in y = 0 facing +y, instanced at the identity.
void add_ground(Scene& scene, float half, Vec3f color) {
    const uint32_t material = add_material(scene, diffuse("ground", color));
    Mesh ground;
    ground.name = "ground";
    ground.positions = {{-half, 0, half}, {half, 0, half}, {half, 0, -half}, {-half, 0, -half}};
    ground.normals.assign(4, Vec3f(0, 1, 0));
    ground.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    ground.indices = {0, 1, 2, 0, 2, 3};
    ground.material_ids = {material, material};
    scene.instances.push_back({add_mesh(scene, std::move(ground)), Affine3f::identity()});
}


void set_timing(Animation& animation) {
    animation.start = 0.0f;
    animation.frames_per_second = kAnimatedSceneFps;
    animation.end = frame_time(kAnimatedSceneFrames - 1);
}

// A node whose translation and rotation are Linear tracks (slerped rotations).
AnimatedNode rigid_node(const std::string& name) {
    AnimatedNode node;
    node.name = name;
    node.translation_track.width = 3;
    node.rotation_track.width = 4;
    return node;
}

void add_key(AnimatedNode& node, int frame, Vec3f p, Vec4f q) {
    const float t = frame_time(frame);
    if (frame == 0) {
        node.translation = p;
        node.rotation = q;
    }
    node.translation_track.times.push_back(t);
    node.translation_track.values.insert(node.translation_track.values.end(), {p.x, p.y, p.z});
    node.rotation_track.times.push_back(t);
    node.rotation_track.values.insert(node.rotation_track.values.end(), {q.x, q.y, q.z, q.w});
}

// The faces of a cube as integer frames with cross(u, v) = n (outward).
struct CubeFace {
    int n[3], u[3], v[3];
};
constexpr CubeFace kCubeFaces[6] = {
    {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}},  {{-1, 0, 0}, {0, 0, 1}, {0, 1, 0}}, {{0, 1, 0}, {0, 0, 1}, {1, 0, 0}},
    {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}}, {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}},  {{0, 0, -1}, {0, 1, 0}, {1, 0, 0}}};

// A closed surface over the cube's six faces of n x n cells (12 n^2
// triangles), welded at the seams (integer lattice keys), each vertex
// shape(unit direction) with directions spread by the equal-angle cube map.
// Area-weighted vertex normals.
template <class Shape>
Mesh make_cube_sphere(const std::string& name, int n, uint32_t material, Shape&& shape) {
    Mesh mesh;
    mesh.name = name;
    const auto row = size_t(n) + 1;
    const auto side = uint64_t(2 * n + 1);
    std::unordered_map<uint64_t, uint32_t> welded;
    welded.reserve(6 * row * row);
    std::vector<uint32_t> grid(row * row);
    for (const CubeFace& f : kCubeFaces) {
        for (int j = 0; j <= n; ++j) {
            for (int i = 0; i <= n; ++i) {
                int c[3];
                for (int k = 0; k < 3; ++k) c[k] = f.n[k] * n + f.u[k] * (2 * i - n) + f.v[k] * (2 * j - n);
                const uint64_t key = (uint64_t(c[0] + n) * side + uint64_t(c[1] + n)) * side + uint64_t(c[2] + n);
                const auto [it, fresh] = welded.try_emplace(key, uint32_t(mesh.positions.size()));
                if (fresh) {
                    auto warp = [n](int v) { return std::tan(0.25f * kPi * float(v) / float(n)); };
                    mesh.positions.push_back(shape(normalize(Vec3f(warp(c[0]), warp(c[1]), warp(c[2])))));
                }
                grid[size_t(j) * row + size_t(i)] = it->second;
            }
        }
        for (size_t j = 0; j < size_t(n); ++j) {
            for (size_t i = 0; i < size_t(n); ++i) {
                const uint32_t v00 = grid[j * row + i], v10 = grid[j * row + i + 1];
                const uint32_t v01 = grid[(j + 1) * row + i], v11 = grid[(j + 1) * row + i + 1];
                mesh.indices.insert(mesh.indices.end(), {v00, v10, v11, v00, v11, v01});
            }
        }
    }
    mesh.material_ids.assign(mesh.triangle_count(), material);
    mesh.compute_vertex_normals();
    return mesh;
}

// A lumpy rock around the unit sphere: a radial displacement by fBm (so the
// surface stays star-shaped and cannot intersect itself) with ridged detail.
Vec3f rock_point(Vec3f d, uint32_t seed, int octaves) {
    const float lumps = fbm3(d * 1.6f + Vec3f(17.0f), seed, octaves);
    const float ridge = 1.0f - std::fabs(2.0f * fbm3(d * 6.0f + Vec3f(5.0f), seed + 101u, 3) - 1.0f);
    return d * (0.45f + 1.1f * lumps + 0.12f * ridge);
}

// A welded torus around the y axis (no seam vertices): rings * sides * 2 triangles.
Mesh make_torus(const std::string& name, float major, float minor, int rings, int sides, uint32_t material) {
    Mesh mesh;
    mesh.name = name;
    for (int i = 0; i < rings; ++i) {
        const float phi = 2.0f * kPi * float(i) / float(rings);
        const Vec3f radial(std::cos(phi), 0.0f, -std::sin(phi));
        for (int j = 0; j < sides; ++j) {
            const float theta = 2.0f * kPi * float(j) / float(sides);
            const Vec3f n = radial * std::cos(theta) + Vec3f(0, 1, 0) * std::sin(theta);
            mesh.positions.push_back(radial * major + n * minor);
            mesh.normals.push_back(n);
        }
    }
    auto vertex = [&](int i, int j) { return uint32_t((i % rings) * sides + j % sides); };
    for (int i = 0; i < rings; ++i)
        for (int j = 0; j < sides; ++j)
            mesh.indices.insert(mesh.indices.end(), {vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1),
                                                     vertex(i, j), vertex(i + 1, j + 1), vertex(i, j + 1)});
    mesh.material_ids.assign(mesh.triangle_count(), material);
    return mesh;
}

// ============================== explode ==============================

constexpr int kExplodeFrame = 15;         // intact up to frame 15 (0.5 s)
constexpr int kExplodeSubsteps = 4;
constexpr uint32_t kNoLabel = 0xffffffffu;

// Each triangle's neighbours across its edges (kNoLabel where open), from
// the sorted (edge, triangle) list.
std::vector<std::array<uint32_t, 3>> triangle_neighbours(const Mesh& mesh) {
    const size_t triangles = mesh.triangle_count();
    std::vector<std::pair<uint64_t, uint32_t>> edges;
    edges.reserve(3 * triangles);
    for (size_t t = 0; t < triangles; ++t) {
        for (int e = 0; e < 3; ++e) {
            const uint32_t a = mesh.indices[3 * t + size_t(e)], b = mesh.indices[3 * t + size_t((e + 1) % 3)];
            edges.emplace_back((uint64_t(std::min(a, b)) << 32) | std::max(a, b), uint32_t(t));
        }
    }
    std::sort(edges.begin(), edges.end());
    std::vector<std::array<uint32_t, 3>> neighbours(triangles, {kNoLabel, kNoLabel, kNoLabel});
    auto link = [&](uint32_t t, uint32_t other) {
        for (uint32_t& slot : neighbours[t])
            if (slot == kNoLabel) return void(slot = other);
    };
    for (size_t k = 0; k + 1 < edges.size(); ++k) {
        if (edges[k].first != edges[k + 1].first) continue;
        link(edges[k].second, edges[k + 1].second);
        link(edges[k + 1].second, edges[k].second);
        ++k;
    }
    return neighbours;
}

Vec3f centroid(const Mesh& mesh, size_t t) {
    return (mesh.positions[mesh.indices[3 * t]] + mesh.positions[mesh.indices[3 * t + 1]] +
            mesh.positions[mesh.indices[3 * t + 2]]) / 3.0f;
}

// A fragment label per triangle: multi-source Dijkstra over the dual graph
// from `count` random seed triangles. A triangle takes the label of the
// settled neighbour it was reached from, so every fragment is edge-connected.
std::vector<uint32_t> grow_fragments(const Mesh& mesh, uint32_t count, uint32_t seed) {
    const size_t triangles = mesh.triangle_count();
    const auto neighbours = triangle_neighbours(mesh);
    std::vector<Vec3f> centres(triangles);
    for (size_t t = 0; t < triangles; ++t) centres[t] = centroid(mesh, t);
    std::vector<float> dist(triangles, std::numeric_limits<float>::infinity());
    std::vector<uint32_t> label(triangles, kNoLabel);
    using Item = std::pair<float, uint32_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    HashRng rng(seed, 1);
    for (uint32_t f = 0; f < count; ++f) {
        auto t = uint32_t(rng.next() * float(triangles)) % uint32_t(triangles);
        while (label[t] != kNoLabel) t = (t + 7919u) % uint32_t(triangles);  // a free one, deterministically
        label[t] = f;
        dist[t] = 0.0f;
        queue.emplace(0.0f, t);
    }
    while (!queue.empty()) {
        const auto [d, t] = queue.top();
        queue.pop();
        if (d > dist[t]) continue;
        for (uint32_t nb : neighbours[t]) {
            if (nb == kNoLabel) continue;
            const Vec3f mid = (centres[t] + centres[nb]) * 0.5f;
            const float rough = 0.25f + 1.5f * value_noise3(mid * 9.0f, seed + 7u);  // jagged cracks
            const float next = d + length(centres[nb] - centres[t]) * rough;
            if (next < dist[nb]) {
                dist[nb] = next;
                label[nb] = label[t];
                queue.emplace(next, nb);
            }
        }
    }
    return label;
}

struct Fragment {
    Mesh mesh;      // relative to `center`
    Vec3f center;   // mean of its vertices, in world space at frame 0
};

// One mesh per label: its triangles in order, its vertices re-indexed (shared
// within the fragment, duplicated along the cracks) around their mean.
std::vector<Fragment> split_fragments(const Mesh& rock, const std::vector<uint32_t>& label, uint32_t count,
                                      const std::vector<uint32_t>& materials) {
    std::vector<std::vector<uint32_t>> members(count);
    for (size_t t = 0; t < label.size(); ++t) members[label[t]].push_back(uint32_t(t));
    std::vector<Fragment> fragments(count);
    std::vector<uint32_t> local(rock.vertex_count(), kNoLabel);
    for (uint32_t f = 0; f < count; ++f) {
        Mesh& mesh = fragments[f].mesh;
        mesh.name = "fragment" + std::to_string(f);
        for (uint32_t t : members[f]) {
            for (int k = 0; k < 3; ++k) {
                const uint32_t v = rock.indices[3 * size_t(t) + size_t(k)];
                if (local[v] == kNoLabel) {
                    local[v] = uint32_t(mesh.positions.size());
                    mesh.positions.push_back(rock.positions[v]);
                    mesh.normals.push_back(rock.normals[v]);
                }
                mesh.indices.push_back(local[v]);
            }
        }
        Vec3f center(0.0f);
        for (const Vec3f& p : mesh.positions) center += p;
        center = center / float(std::max<size_t>(1, mesh.positions.size()));
        for (Vec3f& p : mesh.positions) p -= center;
        for (uint32_t t : members[f])
            for (int k = 0; k < 3; ++k) local[rock.indices[3 * size_t(t) + size_t(k)]] = kNoLabel;
        mesh.material_ids.assign(mesh.triangle_count(), materials[pcg_hash(f) % materials.size()]);
        fragments[f].center = center;
    }
    return fragments;
}

// Fragment f's flight: at rest to kExplodeFrame, then launched away from
// `origin` and spinning, under gravity, bouncing on y = 0 by its lowest
// vertex (restitution, ground friction, spin damping). One key per frame.
void fly_fragment(const Fragment& fragment, Vec3f origin, uint32_t seed, uint32_t f, AnimatedNode& node) {
    HashRng rng(seed, 1000u + f);
    const Vec3f away = fragment.center - origin;
    const Vec3f out = length(away) > 1e-6f ? normalize(away) : Vec3f(0, 1, 0);
    Vec3f v = out * rng.range(1.5f, 4.0f) + Vec3f(0.0f, rng.range(1.0f, 3.0f), 0.0f);
    Vec3f w = rng.unit_vector() * rng.range(2.0f, 9.0f);
    Vec3f p = fragment.center;
    Vec4f q{0, 0, 0, 1};
    const float dt = 1.0f / (kAnimatedSceneFps * float(kExplodeSubsteps));
    for (int frame = 0; frame < kAnimatedSceneFrames; ++frame) {
        if (frame > kExplodeFrame) {
            for (int s = 0; s < kExplodeSubsteps; ++s) {
                v.y -= kGravity * dt;
                p += v * dt;
                q = quat_spin(q, w, dt);
            }
            const Affine3f r = quat_to_affine(q);
            float low = std::numeric_limits<float>::infinity();
            for (const Vec3f& x : fragment.mesh.positions) low = std::fmin(low, r.transform_vector(x).y);
            if (p.y + low < 0.0f) {
                p.y = -low;
                if (v.y < 0.0f) v.y = v.y < -0.6f ? -0.35f * v.y : 0.0f;
                v.x *= 0.6f, v.z *= 0.6f;
                w *= 0.6f;
            }
        }
        add_key(node, frame, p, q);
    }
}

Scene make_explode(size_t total, uint32_t seed) {
    Scene scene;
    const int n = std::max(2, int(std::lround(std::sqrt(double(total - 2) / 12.0))));
    const auto count = uint32_t(std::clamp<size_t>(total / 800, 16, 1024));
    const std::vector<uint32_t> materials = {
        add_material(scene, diffuse("rock_light", {0.62f, 0.55f, 0.47f}, 0.8f)),
        add_material(scene, diffuse("rock_dark", {0.33f, 0.3f, 0.28f}, 0.8f)),
        add_material(scene, diffuse("rock_rust", {0.55f, 0.3f, 0.18f}, 0.8f))};
    const Vec3f stretch(1.25f, 0.9f, 1.0f);
    Mesh rock = make_cube_sphere("rock", n, 0, [&](Vec3f d) { return rock_point(d, seed, 6) * stretch; });
    const float lift = -rock.bounds().lo.y + 1e-3f;  // resting on the ground
    for (Vec3f& p : rock.positions) p.y += lift;
    const Box3f box = rock.bounds();
    const Vec3f origin = (box.lo + box.hi) * 0.5f - Vec3f(0.0f, 0.3f * (box.hi.y - box.lo.y), 0.0f);

    std::vector<Fragment> fragments = split_fragments(rock, grow_fragments(rock, count, seed), count, materials);
    rock = Mesh();
    add_ground(scene, 30.0f, {0.5f, 0.5f, 0.48f});
    Animation& animation = scene.animation;
    set_timing(animation);
    animation.nodes.resize(count, rigid_node(""));
    parallel::for_range<uint32_t>(0, count, 4, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t f = lo; f < hi; ++f) fly_fragment(fragments[f], origin, seed, f, animation.nodes[f]);
    });
    for (uint32_t f = 0; f < count; ++f) {
        animation.nodes[f].name = fragments[f].mesh.name;
        const auto instance = uint32_t(scene.instances.size());
        scene.instances.push_back({add_mesh(scene, std::move(fragments[f].mesh)),
                                   Affine3f::translation(fragments[f].center)});
        animation.instances.push_back({instance, f, Affine3f::identity()});
    }
    add_sun_and_sky(scene, {-0.4f, -1.0f, -0.5f});
    scene.camera = Camera{.eye = {0, 3.5f, 9.0f}, .target = {0, 0.8f, 0}, .up = {0, 1, 0}, .vfov_degrees = 50.0f};
    return scene;
}

// ============================== cloth ==============================

constexpr Vec3f kBallCenter{0.0f, 0.7f, 0.0f};
constexpr float kBallRadius = 0.7f;
constexpr float kClothSide = 3.0f;
constexpr float kClothHeight = 1.75f;
constexpr int kClothMaxSimSide = 48;
constexpr int kClothSubsteps = 16;
constexpr int kClothIterations = 2;
constexpr float kClothThickness = 0.02f;   // simulated particles keep this far from the ball
constexpr float kClothOffset = 0.008f;     // rendered vertices keep this far from ball and ground
constexpr size_t kClothNormalKeyLimit = 8000000;  // vertices x frames with normals stored

// Position-based dynamics on an n x n particle grid (row j along z, column
// i along x): distance constraints, then collisions, per iteration.
class ClothSim {
public:
    ClothSim(int n, Vec3f corner, float side, uint32_t seed) : n_(n) {
        const float h = side / float(n - 1);
        HashRng rng(seed, 2);
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i)
                x_.push_back(corner + Vec3f(float(i) * h, 0.002f * rng.range(-1.0f, 1.0f), float(j) * h));
        v_.assign(x_.size(), Vec3f(0.0f));
        p_ = x_;
        for (const auto& [di, dj, stiffness] : {std::tuple{1, 0, 1.0f}, {0, 1, 1.0f},    // structural
                                                {1, 1, 0.9f}, {1, -1, 0.9f},             // shear
                                                {2, 0, 0.3f}, {0, 2, 0.3f}})             // bend
            add_links(di, dj, stiffness);
    }
    void step_frame() {
        const float dt = 1.0f / (kAnimatedSceneFps * float(kClothSubsteps));
        for (int s = 0; s < kClothSubsteps; ++s) substep(dt);
    }
    [[nodiscard]] const std::vector<Vec3f>& positions() const { return x_; }

private:
    struct Link {
        uint32_t a, b;
        float rest, stiffness;
    };
    void add_links(int di, int dj, float stiffness) {
        for (int j = 0; j < n_; ++j)
            for (int i = 0; i < n_; ++i) {
                const int i2 = i + di, j2 = j + dj;
                if (i2 < 0 || i2 >= n_ || j2 < 0 || j2 >= n_) continue;
                const auto a = uint32_t(j * n_ + i), b = uint32_t(j2 * n_ + i2);
                links_.push_back({a, b, length(x_[b] - x_[a]), stiffness});
            }
    }
    // Pushes p out of the ball and above the ground; returns the contact normal (0 if none).
    static Vec3f collide(Vec3f& p) {
        Vec3f normal(0.0f);
        const Vec3f d = p - kBallCenter;
        const float r = length(d), reach = kBallRadius + kClothThickness;
        if (r < reach && r > 1e-6f) {
            normal = d / r;
            p = kBallCenter + normal * reach;
        }
        if (p.y < 0.5f * kClothThickness) {
            p.y = 0.5f * kClothThickness;
            normal = {0.0f, 1.0f, 0.0f};
        }
        return normal;
    }
    void substep(float dt);

    int n_;
    std::vector<Vec3f> x_, v_, p_;
    std::vector<Link> links_;
};

void ClothSim::substep(float dt) {
    for (size_t k = 0; k < x_.size(); ++k) {
        v_[k].y -= kGravity * dt;
        v_[k] *= 0.999f;
        p_[k] = x_[k] + v_[k] * dt;
    }
    for (int iteration = 0; iteration < kClothIterations; ++iteration) {
        for (const Link& link : links_) {
            const Vec3f d = p_[link.b] - p_[link.a];
            const float len = length(d);
            if (len < 1e-9f) continue;
            const Vec3f fix = d * (0.5f * link.stiffness * (len - link.rest) / len);
            p_[link.a] += fix;
            p_[link.b] -= fix;
        }
        for (Vec3f& p : p_) collide(p);
    }
    for (size_t k = 0; k < x_.size(); ++k) {
        Vec3f v = (p_[k] - x_[k]) / dt;
        Vec3f probe = p_[k] - Vec3f(0.0f, 1e-4f, 0.0f);
        const Vec3f normal = collide(probe);
        if (normal.y != 0.0f || normal.x != 0.0f || normal.z != 0.0f) {  // friction at contacts
            const Vec3f vn = normal * dot(v, normal);
            v = vn + (v - vn) * 0.5f;
        }
        x_[k] = p_[k];
        v_[k] = v;
    }
}

// Catmull-Rom taps from the m-point simulated axis onto the n-point
// rendered one, with linear extrapolation past the ends (so a flat grid
// stays evenly spaced): 4 weights on indices base .. base + 3.
struct Taps {
    int base;
    float weight[4];
};

std::vector<Taps> upsample_taps(int m, int n) {
    std::vector<Taps> taps(static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
        const float u = n == 1 ? 0.0f : float(i) * float(m - 1) / float(n - 1);
        const int i0 = std::min(int(u), m - 2);
        const float t = u - float(i0), t2 = t * t, t3 = t2 * t;
        const float w[4] = {0.5f * (-t3 + 2 * t2 - t), 0.5f * (3 * t3 - 5 * t2 + 2), 0.5f * (-3 * t3 + 4 * t2 + t),
                            0.5f * (t3 - t2)};
        Taps& tap = taps[size_t(i)];
        tap.base = std::clamp(i0 - 1, 0, m - 4);
        std::fill(std::begin(tap.weight), std::end(tap.weight), 0.0f);
        for (int k = 0; k < 4; ++k) {
            const int index = i0 - 1 + k;
            auto add = [&](int at, float weight) { tap.weight[at - tap.base] += weight; };
            if (index < 0) add(0, 2 * w[k]), add(1, -w[k]);
            else if (index >= m) add(m - 1, 2 * w[k]), add(m - 2, -w[k]);
            else add(index, w[k]);
        }
    }
    return taps;
}

// The rendered grid (n x n) from the simulated one (m x m), kept outside the
// ball and above the ground.
void upsample_cloth(const std::vector<Vec3f>& sim, int m, const std::vector<Taps>& taps, int n,
                    std::vector<Vec3f>& out) {
    out.resize(size_t(n) * size_t(n));
    parallel::for_range<int>(0, n, 8, [&](int lo, int hi) {
        for (int j = lo; j < hi; ++j) {
            const Taps& tj = taps[size_t(j)];
            for (int i = 0; i < n; ++i) {
                const Taps& ti = taps[size_t(i)];
                Vec3f p(0.0f);
                for (int b = 0; b < 4; ++b)
                    for (int a = 0; a < 4; ++a)
                        p += sim[size_t(tj.base + b) * size_t(m) + size_t(ti.base + a)] *
                             (tj.weight[b] * ti.weight[a]);
                const Vec3f d = p - kBallCenter;
                const float r = length(d);
                const float reach = kBallRadius + kClothOffset;
                if (r < reach && r > 1e-6f) p = kBallCenter + d * (reach / r);
                p.y = std::fmax(p.y, 0.5f * kClothOffset);
                out[size_t(j) * size_t(n) + size_t(i)] = p;
            }
        }
    });
}

// Grid normals by central differences, facing +y on the flat cloth.
void grid_normals(const std::vector<Vec3f>& p, int n, std::vector<Vec3f>& out) {
    out.resize(p.size());
    parallel::for_range<int>(0, n, 16, [&](int lo, int hi) {
        for (int j = lo; j < hi; ++j) {
            for (int i = 0; i < n; ++i) {
                auto at = [&](int a, int b) {
                    return p[size_t(std::clamp(b, 0, n - 1)) * size_t(n) + size_t(std::clamp(a, 0, n - 1))];
                };
                const Vec3f c = cross(at(i, j + 1) - at(i, j - 1), at(i + 1, j) - at(i - 1, j));
                const float len = length(c);
                out[size_t(j) * size_t(n) + size_t(i)] = len > 1e-12f ? c / len : Vec3f(0, 1, 0);
            }
        }
    });
}

Mesh make_cloth_mesh(int n, uint32_t material) {
    Mesh mesh;
    mesh.name = "cloth";
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) mesh.uvs.push_back(Vec2f{float(i) / float(n - 1), float(j) / float(n - 1)});
    for (int j = 0; j + 1 < n; ++j) {
        for (int i = 0; i + 1 < n; ++i) {
            const auto v00 = uint32_t(j * n + i), v10 = v00 + 1, v01 = v00 + uint32_t(n), v11 = v01 + 1;
            mesh.indices.insert(mesh.indices.end(), {v00, v01, v11, v00, v11, v10});  // facing +y
        }
    }
    mesh.material_ids.assign(mesh.triangle_count(), material);
    return mesh;
}

Scene make_cloth(size_t total, uint32_t seed) {
    Scene scene;
    const int ball_n = std::clamp(int(std::lround(std::sqrt(double(total) * 0.033 / 12.0))), 4, 16);
    const double cloth_triangles = std::max(double(total) - 12.0 * ball_n * ball_n - 2.0, 200.0);
    const int n = int(std::lround(std::sqrt(cloth_triangles / 2.0))) + 1;
    const int m = std::min(n, kClothMaxSimSide);
    Material fabric = diffuse("cloth", {0.7f, 0.12f, 0.1f}, 0.9f);
    const uint32_t cloth_material = add_material(scene, fabric);
    Material metal = diffuse("ball", {0.9f, 0.85f, 0.7f}, 0.25f);
    metal.metallic = 1.0f;
    const uint32_t ball_material = add_material(scene, metal);
    add_ground(scene, 30.0f, {0.55f, 0.55f, 0.52f});
    scene.instances.push_back({add_mesh(scene, make_cube_sphere("ball", ball_n, ball_material,
                                                                [](Vec3f d) { return kBallCenter + d * kBallRadius; })),
                               Affine3f::identity()});

    HashRng rng(seed, 3);
    const Vec3f corner(-0.5f * kClothSide + rng.range(-0.2f, 0.2f), kClothHeight,
                       -0.5f * kClothSide + rng.range(-0.2f, 0.2f));
    ClothSim sim(m, corner, kClothSide, seed);
    const std::vector<Taps> taps = upsample_taps(m, n);
    VertexKeyframes keys;
    keys.interpolation = Interpolation::Linear;
    const bool with_normals = size_t(n) * size_t(n) * kAnimatedSceneFrames <= kClothNormalKeyLimit;
    for (int frame = 0; frame < kAnimatedSceneFrames; ++frame) {
        if (frame > 0) sim.step_frame();
        keys.times.push_back(frame_time(frame));
        upsample_cloth(sim.positions(), m, taps, n, keys.positions.emplace_back());
        if (with_normals) grid_normals(keys.positions.back(), n, keys.normals.emplace_back());
    }
    Mesh cloth = make_cloth_mesh(n, cloth_material);
    cloth.positions = keys.positions.front();
    if (with_normals) cloth.normals = keys.normals.front();
    keys.mesh = add_mesh(scene, std::move(cloth));
    scene.instances.push_back({keys.mesh, Affine3f::identity()});
    set_timing(scene.animation);
    scene.animation.vertex_keyframes.push_back(std::move(keys));
    add_sun_and_sky(scene, {-0.5f, -1.0f, -0.3f});
    scene.camera = Camera{.eye = {0.5f, 2.6f, 4.6f}, .target = {0, 0.6f, 0}, .up = {0, 1, 0}, .vfov_degrees = 45.0f};
    return scene;
}

// ============================== nbody ==============================

constexpr int kBodySubsteps = 8;
constexpr float kBodyMinRadius = 0.1f, kBodyMaxRadius = 0.22f;
constexpr int kBodyShapes = 4;  // sphere, rock, rounded box, torus
constexpr int kBodyColors = 4;

struct Body {
    Vec3f p, v, w;
    Vec4f q;
    float r, inv_mass, inv_inertia;  // a solid sphere of radius r: I = 0.4 m r^2
};

// Sequential impulses between spheres and against the box's planes.
class BodySim {
public:
    BodySim(std::vector<Body> bodies, float half_width) : bodies_(std::move(bodies)), half_(half_width) {}
    void step_frame() {
        const float dt = 1.0f / (kAnimatedSceneFps * float(kBodySubsteps));
        for (int s = 0; s < kBodySubsteps; ++s) substep(dt);
    }
    // Pushes overlapping bodies apart without touching their velocities.
    void relax(int passes) {
        for (int pass = 0; pass < passes; ++pass) contacts(false);
    }
    [[nodiscard]] const std::vector<Body>& bodies() const { return bodies_; }

private:
    void substep(float dt);
    void contacts(bool impulses);
    static void resolve_pair(Body& a, Body& b, bool impulses);
    static void resolve_plane(Body& b, Vec3f n, float offset, bool impulses);

    std::vector<Body> bodies_;
    float half_;
    std::vector<std::pair<float, uint32_t>> sweep_;
};

// The impulse j along the contact tangent opposing `slip` (Coulomb-limited by
// mu * jn), for a contact whose effective inverse mass is `inv_mass`.
float friction_impulse(Vec3f slip, float jn, float inv_mass) {
    return std::fmin(0.3f * jn, length(slip) / (3.5f * inv_mass));
}

void BodySim::resolve_pair(Body& a, Body& b, bool impulses) {
    const Vec3f d = b.p - a.p;
    const float reach = a.r + b.r, dist2 = length_squared(d);
    if (dist2 >= reach * reach) return;
    const float dist = std::sqrt(dist2);
    const Vec3f n = dist > 1e-6f ? d / dist : Vec3f(0, 1, 0);
    const float inv = a.inv_mass + b.inv_mass;
    const float depth = reach - dist;
    a.p -= n * (depth * a.inv_mass / inv);
    b.p += n * (depth * b.inv_mass / inv);
    if (!impulses) return;
    const Vec3f ra = n * a.r, rb = n * (-b.r);
    const Vec3f rel = (b.v + cross(b.w, rb)) - (a.v + cross(a.w, ra));
    const float vn = dot(rel, n);
    if (vn >= 0.0f) return;
    const float jn = -1.55f * vn / inv;  // restitution 0.55
    a.v -= n * (jn * a.inv_mass);
    b.v += n * (jn * b.inv_mass);
    const Vec3f slip = rel - n * vn;
    if (length_squared(slip) < 1e-12f) return;
    const Vec3f t = normalize(slip);
    const Vec3f j = t * friction_impulse(slip, jn, inv);  // on a along +t, on b along -t
    a.v += j * a.inv_mass, b.v -= j * b.inv_mass;
    a.w += cross(ra, j) * a.inv_inertia, b.w += cross(rb, -j) * b.inv_inertia;
}

// Keeps the sphere on the positive side of dot(n, p) = offset.
void BodySim::resolve_plane(Body& b, Vec3f n, float offset, bool impulses) {
    const float depth = offset + b.r - dot(n, b.p);
    if (depth <= 0.0f) return;
    b.p += n * depth;
    if (!impulses) return;
    const Vec3f arm = n * (-b.r);
    const Vec3f rel = b.v + cross(b.w, arm);
    const float vn = dot(rel, n);
    if (vn >= 0.0f) return;
    const float jn = -1.45f * vn / b.inv_mass;  // restitution 0.45
    b.v += n * (jn * b.inv_mass);
    const Vec3f slip = rel - n * vn;
    if (length_squared(slip) < 1e-12f) return;
    const Vec3f j = normalize(slip) * -friction_impulse(slip, jn, b.inv_mass);
    b.v += j * b.inv_mass;
    b.w += cross(arm, j) * b.inv_inertia;
}

void BodySim::substep(float dt) {
    for (Body& b : bodies_) {
        b.v.y -= kGravity * dt;
        b.v *= 0.9995f;
        b.w *= 0.998f;
        b.p += b.v * dt;
        b.q = quat_spin(b.q, b.w, dt);
    }
    contacts(true);
    contacts(true);
    relax(4);  // what the impulses left overlapping (stacks on the floor)
}

// One Gauss-Seidel pass over the overlapping pairs (sweep and prune on x,
// in sorted order) and the box's planes.
void BodySim::contacts(bool impulses) {
    sweep_.clear();
    for (uint32_t k = 0; k < bodies_.size(); ++k) sweep_.emplace_back(bodies_[k].p.x - bodies_[k].r, k);
    std::sort(sweep_.begin(), sweep_.end());
    for (size_t s = 0; s < sweep_.size(); ++s) {
        Body& a = bodies_[sweep_[s].second];
        const float right = a.p.x + a.r;
        for (size_t u = s + 1; u < sweep_.size() && sweep_[u].first <= right; ++u)
            resolve_pair(a, bodies_[sweep_[u].second], impulses);
    }
    if (half_ <= 0.0f) return;  // no box (the heap being relaxed)
    for (Body& b : bodies_) {
        resolve_plane(b, {0, 1, 0}, 0.0f, impulses);
        for (const Vec3f wall : {Vec3f(1, 0, 0), Vec3f(-1, 0, 0), Vec3f(0, 0, 1), Vec3f(0, 0, -1)})
            resolve_plane(b, wall, -half_, impulses);
    }
}

// The four shapes, scaled to a bounding radius of 1, each about `budget` triangles.
Mesh make_body_shape(int shape, int budget, uint32_t material, uint32_t seed) {
    const int m = std::max(1, int(std::lround(std::sqrt(double(budget) / 12.0))));
    Mesh mesh;
    if (shape == 0) mesh = make_cube_sphere("sphere", m, material, [](Vec3f d) { return d; });
    else if (shape == 1) mesh = make_cube_sphere("rock", m, material, [&](Vec3f d) { return rock_point(d, seed, 4); });
    else if (shape == 2) {
        mesh = make_cube_sphere("box", m, material, [](Vec3f d) {
            const float s = std::pow(std::pow(std::fabs(d.x), 6.0f) + std::pow(std::fabs(d.y), 6.0f) +
                                         std::pow(std::fabs(d.z), 6.0f), 1.0f / 6.0f);
            return d / s;
        });
    } else {
        const int k = std::max(3, int(std::lround(std::sqrt(double(budget) / 4.0))));
        mesh = make_torus("torus", 0.7f, 0.3f, 2 * k, k, material);
    }
    float radius = 0.0f;
    for (const Vec3f& p : mesh.positions) radius = std::fmax(radius, length(p));
    for (Vec3f& p : mesh.positions) p = p / radius;
    return mesh;
}

// The bodies' radii, their places in one dense heap (a squeezed lattice
// ball, relaxed until no two overlap), spins, and a burst away from its centre.
std::vector<Body> make_heap(size_t count, uint32_t seed, float& heap_radius) {
    HashRng rng(seed, 4);
    std::vector<Body> bodies(count);
    for (Body& body : bodies) {
        body.r = rng.range(kBodyMinRadius, kBodyMaxRadius);
        body.inv_mass = 1.0f / (body.r * body.r * body.r);
        body.inv_inertia = 2.5f * body.inv_mass / (body.r * body.r);
    }
    const float spacing = 1.6f * kBodyMinRadius + 0.6f * kBodyMaxRadius;  // below the mean diameter: squeezed
    const int reach = int(std::ceil(std::cbrt(double(count)))) + 1, side = 2 * reach + 1;
    std::vector<std::pair<int, int>> cells;  // (squared lattice distance, linear index), nearest first
    for (int k = 0; k < side * side * side; ++k) {
        const int x = k % side - reach, y = k / side % side - reach, z = k / (side * side) - reach;
        cells.emplace_back(x * x + y * y + z * z, k);
    }
    std::sort(cells.begin(), cells.end());
    for (size_t b = 0; b < count; ++b) {
        const int k = cells[b].second;
        const Vec3f cell(float(k % side - reach), float(k / side % side - reach), float(k / (side * side) - reach));
        const Vec3f jitter(rng.range(-0.01f, 0.01f), rng.range(-0.01f, 0.01f), rng.range(-0.01f, 0.01f));
        bodies[b].p = cell * spacing + jitter;
    }
    BodySim relaxed(std::move(bodies), 0.0f);
    relaxed.relax(200);
    bodies = relaxed.bodies();
    heap_radius = 0.0f;
    for (const Body& body : bodies) heap_radius = std::fmax(heap_radius, length(body.p) + body.r);
    for (Body& body : bodies) {
        const Vec3f out = length(body.p) > 1e-6f ? normalize(body.p) : Vec3f(0, 1, 0);
        body.p.y += heap_radius + 0.3f;
        const Vec3f scatter(rng.range(-0.5f, 0.5f), rng.range(0.0f, 1.0f), rng.range(-0.5f, 0.5f));
        body.v = out * rng.range(1.5f, 4.0f) + scatter;
        body.w = rng.unit_vector() * rng.range(0.0f, 8.0f);
        body.q = quat_axis_angle(rng.unit_vector(), rng.range(0.0f, 2.0f * kPi));
    }
    return bodies;
}

Scene make_nbody(size_t total, uint32_t seed) {
    Scene scene;
    const size_t guess = std::clamp<size_t>(total / 500, 8, 1024);
    const auto budget = int(total / guess);
    const Vec3f colors[kBodyColors] = {
        {0.8f, 0.25f, 0.2f}, {0.2f, 0.45f, 0.8f}, {0.85f, 0.75f, 0.3f}, {0.3f, 0.7f, 0.35f}};
    uint32_t shapes[kBodyShapes][kBodyColors];
    double mean = 0.0;
    for (int c = 0; c < kBodyColors; ++c) {
        const uint32_t material = add_material(scene, diffuse("body" + std::to_string(c), colors[c], 0.5f));
        for (int s = 0; s < kBodyShapes; ++s) {
            Mesh mesh = make_body_shape(s, budget, material, seed + 31u * uint32_t(c));
            mesh.name += std::to_string(c);
            if (c == 0) mean += double(mesh.triangle_count()) / kBodyShapes;
            shapes[s][c] = add_mesh(scene, std::move(mesh));
        }
    }
    const auto count = std::max<size_t>(2, size_t(std::lround(double(total - 2) / mean)));
    float heap_radius = 0.0f;
    std::vector<Body> heap = make_heap(count, seed, heap_radius);
    const float half = std::max(3.0f, 2.2f * heap_radius);  // the box's walls
    BodySim sim(std::move(heap), half);
    add_ground(scene, 4.0f * half, {0.55f, 0.55f, 0.5f});
    Animation& animation = scene.animation;
    set_timing(animation);
    for (size_t b = 0; b < count; ++b) animation.nodes.push_back(rigid_node("body" + std::to_string(b)));
    for (int frame = 0; frame < kAnimatedSceneFrames; ++frame) {
        if (frame > 0) sim.step_frame();
        for (size_t b = 0; b < count; ++b) add_key(animation.nodes[b], frame, sim.bodies()[b].p, sim.bodies()[b].q);
    }
    for (size_t b = 0; b < count; ++b) {
        const AnimatedNode& node = animation.nodes[b];  // rest values = frame 0
        const Affine3f local = Affine3f::scale(Vec3f(sim.bodies()[b].r));
        const auto instance = uint32_t(scene.instances.size());
        const uint32_t mesh = shapes[b % kBodyShapes][pcg_hash(seed ^ uint32_t(b)) % kBodyColors];
        const Affine3f frame0 = Affine3f::translation(node.translation) * quat_to_affine(node.rotation) * local;
        scene.instances.push_back({mesh, frame0});
        animation.instances.push_back({instance, uint32_t(b), local});
    }
    add_sun_and_sky(scene, {-0.4f, -1.0f, -0.5f});
    scene.camera = Camera{.eye = {0, 1.2f * half, 2.6f * half}, .target = {0, 0.3f * half, 0}, .up = {0, 1, 0},
                          .vfov_degrees = 45.0f};
    return scene;
}

// "800k" -> 800000; 0 when the text is not a count.
size_t parse_size(const std::string& text) {
    double value = 0.0;
    const char* end = text.data() + text.size();
    const auto [rest, error] = std::from_chars(text.data(), end, value, std::chars_format::fixed);
    if (error != std::errc() || text.empty() || text[0] == '-' || text[0] == '+') return 0;
    double scale = 1.0;
    if (rest + 1 == end && (*rest == 'k' || *rest == 'K')) scale = 1e3;
    else if (rest + 1 == end && (*rest == 'm' || *rest == 'M')) scale = 1e6;
    else if (rest != end) return 0;
    const double count = std::round(value * scale);
    return std::isfinite(count) && count >= 1.0 && count < 1e12 ? size_t(count) : 0;
}

uint32_t parse_seed(const std::string& name, const std::string& text) {
    uint64_t seed = 0;
    const auto [rest, error] = std::from_chars(text.data(), text.data() + text.size(), seed);
    if (text.empty() || error != std::errc() || rest != text.data() + text.size() || seed > 0xffffffffull)
        throw Error("builtin:" + name + ": bad seed '" + text + "' (expected an integer from 0 to 4294967295)");
    return uint32_t(seed);
}

std::string kind_of(const std::string& name) { return name.substr(0, name.find_first_of("@#")); }

}  // namespace

std::vector<std::string> animated_scene_names() { return {"explode", "cloth", "nbody"}; }

bool is_animated_scene_name(const std::string& name) {
    const auto kinds = animated_scene_names();
    return std::find(kinds.begin(), kinds.end(), kind_of(name)) != kinds.end();
}

AnimatedSceneSpec parse_animated_scene_name(const std::string& name) {
    if (!is_animated_scene_name(name))
        throw Error("builtin:" + name + ": not an animated scene (explode, cloth, nbody)");
    AnimatedSceneSpec spec;
    spec.kind = kind_of(name);
    const size_t at = name.find('@'), hash = name.find('#');
    if (hash != std::string::npos && at != std::string::npos && hash < at)
        throw Error("builtin:" + name + ": the size goes before the seed (NAME@SIZE#SEED)");
    if (at != std::string::npos) {
        const std::string text = name.substr(at + 1, hash == std::string::npos ? std::string::npos : hash - at - 1);
        spec.triangles = parse_size(text);
        if (spec.triangles == 0)
            throw Error("builtin:" + name + ": bad size '" + text +
                        "' (expected a triangle count like 250000, 800k or 1.5m)");
        if (spec.triangles < kAnimatedSceneMinTriangles || spec.triangles > kAnimatedSceneMaxTriangles)
            throw Error("builtin:" + name + ": size " + std::to_string(spec.triangles) +
                        " is outside 1k .. 2m triangles");
    }
    if (hash != std::string::npos) spec.seed = parse_seed(name, name.substr(hash + 1));
    return spec;
}

Scene make_animated_scene(const std::string& name) {
    const AnimatedSceneSpec spec = parse_animated_scene_name(name);
    if (spec.kind == "explode") return make_explode_scene(spec.triangles, spec.seed);
    if (spec.kind == "cloth") return make_cloth_scene(spec.triangles, spec.seed);
    return make_nbody_scene(spec.triangles, spec.seed);
}

Scene make_explode_scene(size_t triangles, uint32_t seed) {
    return make_explode(triangles ? triangles : kExplodeDefaultTriangles, seed);
}

Scene make_cloth_scene(size_t triangles, uint32_t seed) {
    return make_cloth(triangles ? triangles : kClothDefaultTriangles, seed);
}

Scene make_nbody_scene(size_t triangles, uint32_t seed) {
    return make_nbody(triangles ? triangles : kNbodyDefaultTriangles, seed);
}

}  // namespace rf
