// Procedural massive scenes of unique geometry, streamed object by object
// (docs/paged-scenes.md): test scenes from a few thousand to billions of
// triangles without downloads, for the paged format and its caches.
//
// Layout: a square terrain of side W (growing with the square root of the
// budget, so the density of statues stays about the same) is an fBm of
// Perlin gradient noise sampled on a regular grid and cut into tiles of at
// most 256 x 256 cells, one object each; vertex heights and normals are
// functions of the global grid index, so tiles meet without cracks. The
// statues get about 70% of the budget: a greedy plan draws copies (a
// source: bunny, dragon or blob, and a subdivision level from the upper
// half of those that fit the rest of the budget and max_object_triangles)
// until no copy fits, the terrain's grid then takes what is left, so the
// total is within a fraction of a percent of the target. The copies are
// shuffled onto a jittered grid, each inside its cell, resting on the
// lowest terrain height under its footprint.
//
// Uniqueness: every copy has its own scale, rotation about y, material and
// noise displacement along the normal (about 1.5% of its size, two
// octaves); blobs also get their own shape (a radial noise on the sphere).
// Subdivision splits each triangle into four at its edge midpoints; a
// statue's midpoints are Phong-tessellation points (Boubekeur & Alexa
// 2008) so that subdivided copies are smooth, not faceted, and the blob's
// are on the sphere. The topology of every (source, level) is built once
// (an open-addressing edge table, no per-vertex maps) and shared by the
// copies; per copy only positions are computed, streaming over arrays.
//
// Memory: one object's buffers are reused from copy to copy; a copy larger
// than max_object_triangles (only a source at level 0 can be) is handed to
// the sink in triangle ranges. Determinism: all randomness is a
// counter-based splitmix64 stream keyed by (seed, purpose, index), and the
// arithmetic is +, -, *, /, sqrt and floor only, so a build without fused
// multiply-adds gives the same bits everywhere.
#include "ooc/generate/massive_scene.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"

namespace rf::pack {
namespace {

using Sink = std::function<void(const GeneratedObject&)>;

// ------------------------------------------------------------ random numbers

uint64_t splitmix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

// Purposes of the random streams, so that no two draw the same numbers.
enum class Stream : uint64_t { Plan = 1, Copy, Terrain, Texture, Placement, Prototype };

// The n-th number of a stream is a pure function of (seed, purpose, index, n).
class Rng {
public:
    Rng(uint64_t seed, Stream purpose, uint64_t index = 0)
        : key_(splitmix64(splitmix64(splitmix64(seed) ^ uint64_t(purpose)) ^ index)) {}
    uint64_t next() { return splitmix64(key_ + 0xd1b54a32d192ed03ull * counter_++); }
    uint32_t bits32() { return uint32_t(next() >> 32); }
    float uniform() { return float(next() >> 40) * 0x1p-24f; }  // [0, 1)
    float uniform(float lo, float hi) { return lo + (hi - lo) * uniform(); }
    uint64_t below(uint64_t n) { return next() % n; }  // the modulo bias is negligible for small n

private:
    uint64_t key_;
    uint64_t counter_ = 0;
};

// ------------------------------------------------------------ gradient noise

uint32_t lattice_hash(int32_t x, int32_t y, int32_t z, uint32_t seed) {
    uint32_t h = seed ^ (uint32_t(x) * 0x8da6b343u) ^ (uint32_t(y) * 0xd8163841u) ^
                 (uint32_t(z) * 0xcb1ab31fu);
    h ^= h >> 16;
    h *= 0x7feb352du;
    h ^= h >> 15;
    h *= 0x846ca68bu;
    return h ^ (h >> 16);
}

float fade(float t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }
float mix(float a, float b, float t) { return a + (b - a) * t; }

float gradient2(uint32_t h, float x, float y) {
    constexpr float d = 0.70710678f;
    constexpr float g[8][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {d, d}, {-d, d}, {d, -d}, {-d, -d}};
    return g[h & 7][0] * x + g[h & 7][1] * y;
}

int32_t wrap(int32_t i, int32_t period) {
    int32_t r = i % period;
    return r < 0 ? r + period : r;
}

// Perlin gradient noise in [-1, 1] (unit gradients reach at most sqrt(2)/2,
// hence the scale); a positive `period` wraps the lattice, for textures that tile.
float gradient_noise2(float x, float y, uint32_t seed, int32_t period = 0) {
    float fx = std::floor(x), fy = std::floor(y);
    float tx = x - fx, ty = y - fy;
    int32_t x0 = int32_t(fx), y0 = int32_t(fy), x1 = x0 + 1, y1 = y0 + 1;
    if (period > 0) {
        x0 = wrap(x0, period), x1 = wrap(x1, period), y0 = wrap(y0, period), y1 = wrap(y1, period);
    }
    float g00 = gradient2(lattice_hash(x0, y0, 0, seed), tx, ty);
    float g10 = gradient2(lattice_hash(x1, y0, 0, seed), tx - 1.0f, ty);
    float g01 = gradient2(lattice_hash(x0, y1, 0, seed), tx, ty - 1.0f);
    float g11 = gradient2(lattice_hash(x1, y1, 0, seed), tx - 1.0f, ty - 1.0f);
    float u = fade(tx), v = fade(ty);
    return 1.41421356f * mix(mix(g00, g10, u), mix(g01, g11, u), v);
}

// Improved noise's twelve edge gradients, four repeated (Perlin 2002), from
// a table rather than branches; the noise is then about [-1, 1].
float gradient3(uint32_t h, float x, float y, float z) {
    static constexpr float g[16][3] = {{1, 1, 0}, {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}, {1, 0, 1}, {-1, 0, 1},
                                       {1, 0, -1}, {-1, 0, -1}, {0, 1, 1}, {0, -1, 1}, {0, 1, -1}, {0, -1, -1},
                                       {1, 1, 0}, {0, -1, 1}, {-1, 1, 0}, {0, -1, -1}};
    const float* d = g[h & 15];
    return d[0] * x + d[1] * y + d[2] * z;
}

float gradient_noise3(Vec3f p, uint32_t seed) {
    float fx = std::floor(p.x), fy = std::floor(p.y), fz = std::floor(p.z);
    float tx = p.x - fx, ty = p.y - fy, tz = p.z - fz;
    int32_t x = int32_t(fx), y = int32_t(fy), z = int32_t(fz);
    float c[8];
    for (int k = 0; k < 8; ++k) {
        int dx = k & 1, dy = (k >> 1) & 1, dz = k >> 2;
        c[k] = gradient3(lattice_hash(x + dx, y + dy, z + dz, seed), tx - float(dx), ty - float(dy),
                         tz - float(dz));
    }
    float u = fade(tx), v = fade(ty), w = fade(tz);
    float lo = mix(mix(c[0], c[1], u), mix(c[2], c[3], u), v);
    float hi = mix(mix(c[4], c[5], u), mix(c[6], c[7], u), v);
    return mix(lo, hi, w);
}

// ------------------------------------------------------------ the terrain

constexpr int kMaxOctaves = 12;
constexpr uint32_t kMaxTileCells = 256;

// The terrain's extent and height function depend on the options only (so
// generated_look needs no plan); its grid is set once the statues are planned.
struct Terrain {
    double extent = 1;  // covers [-extent/2, extent/2] in x and z
    float wavelength = 1, amplitude = 1;  // of the first octave; each next halves both
    int octaves = 1;
    uint32_t seed = 0;
    std::array<Vec2f, kMaxOctaves> offsets{};
    uint32_t cells_x = 1, cells_z = 1, tile_cells = 1;

    [[nodiscard]] float height(float x, float z) const {
        float h = 0, amp = amplitude, inv = 1.0f / wavelength;
        for (int o = 0; o < octaves; ++o, amp *= 0.5f, inv *= 2.0f)
            h += amp * gradient_noise2(x * inv + offsets[o].x, z * inv + offsets[o].y, seed + uint32_t(o));
        return h;
    }
    [[nodiscard]] float height_bound() const { return 2.0f * amplitude; }  // the octaves' sum
    [[nodiscard]] float x_at(int64_t i) const { return float(double(i) * (extent / cells_x) - extent / 2); }
    [[nodiscard]] float z_at(int64_t j) const { return float(double(j) * (extent / cells_z) - extent / 2); }
    [[nodiscard]] float tile_size() const { return float(extent / cells_x * tile_cells); }
    [[nodiscard]] uint64_t triangles() const { return 2ull * cells_x * cells_z; }
};

Terrain terrain_shape(const GenerateOptions& options) {
    Terrain t;
    t.extent = 60.0 * std::sqrt(std::max(1.0, double(options.triangles) / 2e6));
    t.wavelength = float(std::min(t.extent / 2, 400.0));
    t.amplitude = 0.12f * t.wavelength;
    // Octaves down to about four cells of a grid holding the whole budget.
    double nominal_cell = t.extent / std::sqrt(double(options.triangles) / 2);
    t.octaves = 1;
    while (t.octaves < kMaxOctaves && double(t.wavelength) / double(1u << t.octaves) >= 4 * nominal_cell)
        ++t.octaves;
    Rng rng(options.seed, Stream::Terrain);
    t.seed = rng.bits32();
    for (Vec2f& offset : t.offsets) offset = {rng.uniform(0, 256), rng.uniform(0, 256)};
    return t;
}

uint64_t integer_sqrt(uint64_t n) {
    uint64_t r = uint64_t(std::sqrt(double(n)));
    while (r * r > n) --r;
    while ((r + 1) * (r + 1) <= n) ++r;
    return r;
}

// The grid nearest `triangles` (2 per cell), in tiles that fit max_object.
void set_terrain_grid(Terrain& t, uint64_t triangles, uint64_t max_object) {
    uint64_t cells_x = std::max<uint64_t>(1, integer_sqrt(triangles / 2));
    uint64_t cells_z = std::max<uint64_t>(1, (triangles + cells_x) / (2 * cells_x));
    t.cells_x = uint32_t(cells_x);
    t.cells_z = uint32_t(cells_z);
    t.tile_cells = uint32_t(std::min<uint64_t>(kMaxTileCells, integer_sqrt(max_object / 2)));
}

Vec3f normalized_or_up(Vec3f v) {
    float len2 = dot(v, v);
    return len2 > 1e-36f ? v * (1.0f / std::sqrt(len2)) : Vec3f{0, 1, 0};
}

// Heights of the tile's vertices and a one-vertex border, for normals by
// central differences that agree with the neighbouring tiles'.
void sample_tile_heights(const Terrain& t, uint32_t i0, uint32_t j0, uint32_t ni, uint32_t nj,
                         std::vector<float>& heights) {
    heights.resize(size_t(ni + 3) * (nj + 3));
    for (uint32_t b = 0; b < nj + 3; ++b) {
        float z = t.z_at(int64_t(j0) + b - 1);
        for (uint32_t a = 0; a < ni + 3; ++a)
            heights[size_t(b) * (ni + 3) + a] = t.height(t.x_at(int64_t(i0) + a - 1), z);
    }
}

constexpr uint32_t kTerrainMaterial = 0, kRockMaterial = 1, kFirstStatueMaterial = 2;
constexpr uint32_t kMaterialCount = 8;

void add_tile_triangles(uint32_t ni, uint32_t nj, GeneratedObject& out) {
    const std::vector<Vec3f>& p = out.positions;
    for (uint32_t b = 0; b < nj; ++b) {
        for (uint32_t a = 0; a < ni; ++a) {
            uint32_t v00 = b * (ni + 1) + a, v10 = v00 + 1, v01 = v00 + ni + 1, v11 = v01 + 1;
            for (std::array<uint32_t, 3> tri : {std::array{v00, v01, v10}, std::array{v10, v01, v11}}) {
                out.indices.insert(out.indices.end(), tri.begin(), tri.end());
                // Steep faces (more than about 37 degrees) are rock.
                Vec3f face = cross(p[tri[1]] - p[tri[0]], p[tri[2]] - p[tri[0]]);
                bool steep = face.y * face.y < 0.64f * dot(face, face);
                out.material_ids.push_back(steep ? kRockMaterial : kTerrainMaterial);
            }
        }
    }
}

void make_terrain_tile(const Terrain& t, uint32_t i0, uint32_t j0, GeneratedObject& out,
                       std::vector<float>& heights) {
    uint32_t ni = std::min(t.tile_cells, t.cells_x - i0), nj = std::min(t.tile_cells, t.cells_z - j0);
    sample_tile_heights(t, i0, j0, ni, nj, heights);
    const size_t row = ni + 3;
    const float dx = float(t.extent / t.cells_x), dz = float(t.extent / t.cells_z);
    const float inv_tile = 1.0f / t.tile_size();
    for (uint32_t b = 1; b <= nj + 1; ++b) {
        float z = t.z_at(int64_t(j0) + b - 1);
        for (uint32_t a = 1; a <= ni + 1; ++a) {
            const float* h = &heights[b * row + a];
            float x = t.x_at(int64_t(i0) + a - 1);
            out.positions.push_back({x, h[0], z});
            out.normals.push_back(normalized_or_up({(h[-1] - h[1]) * dz, 2 * dx * dz, (h[-row] - h[row]) * dx}));
            out.uvs.push_back({x * inv_tile, z * inv_tile});
        }
    }
    add_tile_triangles(ni, nj, out);
}

// ------------------------------------------------------------ statue sources

// One subdivision level: its triangles, and the new vertices' parents (the
// edge endpoints, in the previous level), appended after its vertices.
struct Level {
    std::vector<uint32_t> indices;
    std::vector<std::array<uint32_t, 2>> midpoints;
    uint32_t vertex_count = 0;
};

// Edge midpoints of `parent`, each edge once, found in an open-addressing
// table keyed by the sorted endpoints; every triangle becomes four.
Level subdivide(const Level& parent) {
    const size_t tris = parent.indices.size() / 3;
    const size_t capacity = std::bit_ceil(std::max<size_t>(16, 4 * tris));  // load <= 3/4
    std::vector<uint64_t> keys(capacity, ~0ull);
    std::vector<uint32_t> ids(capacity);
    Level level;
    level.indices.reserve(12 * tris);
    auto midpoint = [&](uint32_t a, uint32_t b) {
        uint64_t key = a < b ? (uint64_t(a) << 32 | b) : (uint64_t(b) << 32 | a);
        size_t slot = size_t(splitmix64(key)) & (capacity - 1);
        for (; keys[slot] != ~0ull; slot = (slot + 1) & (capacity - 1))
            if (keys[slot] == key) return ids[slot];
        keys[slot] = key;
        ids[slot] = parent.vertex_count + uint32_t(level.midpoints.size());
        level.midpoints.push_back({a, b});
        return ids[slot];
    };
    for (size_t t = 0; t < tris; ++t) {
        uint32_t a = parent.indices[3 * t], b = parent.indices[3 * t + 1], c = parent.indices[3 * t + 2];
        uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
        for (uint32_t v : {a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca}) level.indices.push_back(v);
    }
    level.vertex_count = parent.vertex_count + uint32_t(level.midpoints.size());
    return level;
}

struct StatueSource {
    std::string name;
    // Level 0's vertices: a statue's fit a unit box, centred in x and z,
    // standing on y = 0; the blob's are on the unit sphere.
    std::vector<Vec3f> positions, normals;
    bool spherical = false;
    float footprint = 0.5f;  // horizontal radius of any copy, in units of its size
    std::vector<Level> levels;  // [0] the source; the others built on first use

    [[nodiscard]] uint64_t triangles(uint32_t level) const { return (levels[0].indices.size() / 3) << (2 * level); }
    const Level& level(uint32_t l) {
        while (levels.size() <= l) levels.push_back(subdivide(levels.back()));
        return levels[l];
    }
};

void area_weighted_normals(const std::vector<Vec3f>& positions, const std::vector<uint32_t>& indices,
                           std::vector<Vec3f>& normals) {
    normals.assign(positions.size(), Vec3f{0, 0, 0});
    for (size_t t = 0; t < indices.size(); t += 3) {
        uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
        Vec3f face = cross(positions[b] - positions[a], positions[c] - positions[a]);
        normals[a] += face;
        normals[b] += face;
        normals[c] += face;
    }
    for (Vec3f& n : normals) n = normalized_or_up(n);
}

// The scene's triangles in world space, without degenerate index triples
// and unreferenced vertices.
void merge_scene(const Scene& scene, std::vector<Vec3f>& positions, std::vector<uint32_t>& indices) {
    for (const Instance& instance : scene.instances) {
        const Mesh& mesh = scene.meshes[instance.mesh];
        std::vector<uint32_t> remap(mesh.positions.size(), ~0u);
        for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
            uint32_t a = mesh.indices[t], b = mesh.indices[t + 1], c = mesh.indices[t + 2];
            if (a == b || b == c || c == a) continue;
            for (uint32_t v : {a, b, c}) {
                if (remap[v] == ~0u) {
                    remap[v] = uint32_t(positions.size());
                    positions.push_back(instance.transform.transform_point(mesh.positions[v]));
                }
                indices.push_back(remap[v]);
            }
        }
    }
}

std::optional<StatueSource> statue_from_scene(const Scene& scene, const std::string& name) {
    StatueSource s;
    s.name = name;
    s.levels.resize(1);
    merge_scene(scene, s.positions, s.levels[0].indices);
    if (s.levels[0].indices.size() < 12) return std::nullopt;
    Box3f box;
    for (Vec3f p : s.positions) box.extend(p);
    float scale = 1.0f / max_component(box.extent());
    if (!is_finite(box.lo) || !is_finite(box.hi) || !std::isfinite(scale)) return std::nullopt;
    Vec3f origin{box.center().x, box.lo.y, box.center().z};
    float radius = 0;
    for (Vec3f& p : s.positions) {
        p = (p - origin) * scale;
        radius = std::max(radius, std::sqrt(p.x * p.x + p.z * p.z));
    }
    s.footprint = radius + 0.03f;  // the displacement and the Phong bulge
    s.levels[0].vertex_count = uint32_t(s.positions.size());
    area_weighted_normals(s.positions, s.levels[0].indices, s.normals);
    return s;
}

// The first of `paths` that exists and loads; a statue that cannot be read is left out.
std::optional<StatueSource> load_statue(const std::string& name, const std::vector<std::string>& paths) {
    for (const std::string& path : paths) {
        if (!std::filesystem::is_regular_file(path)) continue;
        try {
            LoadOptions load;
            load.load_textures = false;
            load.compute_missing_normals = false;
            if (auto source = statue_from_scene(load_scene(path, load), name)) return source;
        } catch (const Error&) {
        }
    }
    return std::nullopt;
}

// The blob: an icosphere of 320 triangles, shaped per copy.
StatueSource make_blob() {
    const float g = 1.61803399f;
    StatueSource s;
    s.name = "blob";
    s.spherical = true;
    s.footprint = 0.76f;  // 0.5 * (1 + kBlobShape * 1.82) plus the displacement
    s.positions = {{-1, g, 0}, {1, g, 0}, {-1, -g, 0}, {1, -g, 0}, {0, -1, g}, {0, 1, g},
                   {0, -1, -g}, {0, 1, -g}, {g, 0, -1}, {g, 0, 1}, {-g, 0, -1}, {-g, 0, 1}};
    for (Vec3f& p : s.positions) p = normalize(p);
    Level ico;
    ico.indices = {0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8,
                   3, 9, 4, 3, 4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1};
    ico.vertex_count = 12;
    for (int l = 0; l < 2; ++l) {
        ico = subdivide(ico);
        for (auto [a, b] : ico.midpoints) s.positions.push_back(normalize(s.positions[a] + s.positions[b]));
    }
    ico.midpoints.clear();
    s.normals = s.positions;
    s.levels.push_back(std::move(ico));
    return s;
}

std::vector<StatueSource> load_sources(const std::string& dir) {
    std::vector<StatueSource> sources;
    if (!dir.empty()) {
        const std::string bunny = dir + "/stanford-bunny/", dragon = dir + "/stanford-dragon/";
        if (auto s = load_statue("bunny", {bunny + "bun_zipper.ply", bunny + "stanford-bunny.obj"}))
            sources.push_back(std::move(*s));
        if (auto s = load_statue("dragon", {dragon + "dragon_vrip.ply"})) sources.push_back(std::move(*s));
    }
    sources.push_back(make_blob());
    return sources;
}

// ------------------------------------------------------------ the plan

struct PlannedCopy {
    uint32_t source = 0, level = 0;
    uint64_t triangles = 0;
};

struct ScenePlan {
    Terrain terrain;
    std::vector<StatueSource> sources;
    std::vector<PlannedCopy> copies;  // in grid order, row by row
    std::vector<PlannedCopy> prototypes;  // "forest": placed by instances
    uint64_t placements = 0;              // "forest": instances, on the grid below
    uint32_t grid_x = 1, grid_z = 1;      // statue copies' or placements' slots
    uint64_t triangles = 0;
};

constexpr uint32_t kMaxLevel = 12;

// The deepest level of `s` within `remaining` and (above level 0) max_object; -1 if none.
int deepest_level(const StatueSource& s, uint64_t remaining, uint64_t max_object) {
    int deepest = -1;
    for (uint32_t l = 0; l <= kMaxLevel; ++l) {
        uint64_t tris = s.triangles(l);
        if (tris > remaining || (l > 0 && tris > max_object)) break;
        deepest = int(l);
    }
    return deepest;
}

// Copies drawn until none fits the budget: a source by weight, then a level
// from the upper half of those that fit, so copies are not needlessly coarse.
std::vector<PlannedCopy> plan_copies(const std::vector<StatueSource>& sources, uint64_t budget,
                                     const GenerateOptions& options) {
    Rng rng(options.seed, Stream::Plan);
    std::vector<PlannedCopy> copies;
    std::vector<int> deepest(sources.size());
    auto weight = [&](size_t s) { return deepest[s] < 0 ? 0u : (sources[s].spherical ? 3u : 4u); };
    for (uint64_t remaining = budget;;) {
        uint32_t total_weight = 0;
        for (size_t s = 0; s < sources.size(); ++s) {
            deepest[s] = deepest_level(sources[s], remaining, options.max_object_triangles);
            total_weight += weight(s);
        }
        if (total_weight == 0) break;
        uint32_t pick = uint32_t(rng.below(total_weight)), s = 0;
        for (; pick >= weight(s); ++s) pick -= weight(s);
        uint32_t lowest = uint32_t(deepest[s] + 1) / 2;
        uint32_t level = lowest + uint32_t(rng.below(uint32_t(deepest[s]) - lowest + 1));
        copies.push_back({s, level, sources[s].triangles(level)});
        remaining -= copies.back().triangles;
    }
    for (size_t i = copies.size(); i > 1; --i) std::swap(copies[i - 1], copies[rng.below(i)]);
    return copies;
}

void check_options(const GenerateOptions& options) {
    const std::vector<std::string> names = generator_names();
    if (std::find(names.begin(), names.end(), options.name) == names.end()) {
        std::string known;
        for (const std::string& name : names) known += (known.empty() ? "" : ", ") + name;
        throw Error("generate: unknown scene '" + options.name + "' (known: " + known + ")");
    }
    if (options.triangles < kMinGeneratedTriangles || options.triangles > kMaxGeneratedTriangles)
        throw Error("generate: " + std::to_string(options.triangles) + " triangles is outside [" +
                    std::to_string(kMinGeneratedTriangles) + ", " + std::to_string(kMaxGeneratedTriangles) + "]");
    if (options.max_object_triangles < kMinObjectTriangles)
        throw Error("generate: max_object_triangles " + std::to_string(options.max_object_triangles) +
                    " is below " + std::to_string(kMinObjectTriangles));
    if (options.instanced_triangles > kMaxInstancedTriangles)
        throw Error("generate: " + std::to_string(options.instanced_triangles) + " instanced triangles is above " +
                    std::to_string(kMaxInstancedTriangles));
}

// kForestPrototypes prototypes sharing half the unique triangles, each the
// deepest level of its source that fits; enough placements on a square grid
// of slots to show instanced_triangles.
constexpr uint32_t kForestPrototypes = 6;

void plan_forest(ScenePlan& plan, const GenerateOptions& options, uint64_t& unique_statue_triangles) {
    plan.sources = load_sources(options.statue_dir);
    const uint64_t per_prototype = options.triangles / 2 / kForestPrototypes;
    uint64_t shown = 0;
    for (uint32_t k = 0; k < kForestPrototypes; ++k) {
        const uint32_t s = k % uint32_t(plan.sources.size());
        const int level = deepest_level(plan.sources[s], per_prototype, options.max_object_triangles);
        if (level < 0) continue;  // a source larger than its share
        plan.prototypes.push_back({s, uint32_t(level), plan.sources[s].triangles(uint32_t(level))});
        unique_statue_triangles += plan.prototypes.back().triangles;
        shown += plan.prototypes.back().triangles;
    }
    if (plan.prototypes.empty()) throw Error("generate: forest: too few triangles for a prototype");
    const uint64_t average = std::max<uint64_t>(1, shown / plan.prototypes.size());
    const uint64_t target = options.instanced_triangles ? options.instanced_triangles : 25 * options.triangles;
    plan.placements = std::max<uint64_t>(1, (target + average - 1) / average);
    plan.grid_x = uint32_t(integer_sqrt(plan.placements - 1) + 1);
    plan.grid_z = uint32_t(std::max<uint64_t>(1, (plan.placements + plan.grid_x - 1) / plan.grid_x));
}

ScenePlan plan_scene(const GenerateOptions& options) {
    ScenePlan plan;
    plan.terrain = terrain_shape(options);
    uint64_t statue_triangles = 0;
    if (options.name == "terrain-statues") {
        plan.sources = load_sources(options.statue_dir);
        plan.copies = plan_copies(plan.sources, options.triangles / 10 * 7, options);
        for (const PlannedCopy& c : plan.copies) statue_triangles += c.triangles;
        const uint64_t n = plan.copies.size();
        plan.grid_x = uint32_t(n > 0 ? integer_sqrt(n - 1) + 1 : 1);  // ceil(sqrt(n))
        plan.grid_z = uint32_t(std::max<uint64_t>(1, (n + plan.grid_x - 1) / plan.grid_x));
    }
    if (options.name == "forest") plan_forest(plan, options, statue_triangles);
    set_terrain_grid(plan.terrain, options.triangles - statue_triangles, options.max_object_triangles);
    plan.triangles = plan.terrain.triangles() + statue_triangles;
    return plan;
}

// ------------------------------------------------------------ statue copies

constexpr float kBlobShape = 0.25f;        // radial noise of the blob's shape
constexpr float kDisplacement = 0.012f;    // of the size, per octave weight (1 + 0.5)
constexpr float kMaxSizeOfExtent = 0.12f;  // no statue is larger than this share of the terrain

// Where and how one copy stands: drawn from its grid slot alone.
struct CopyPlacement {
    float x = 0, z = 0, base_y = 0, size = 1, cos_yaw = 1, sin_yaw = 0;
    uint32_t material = kFirstStatueMaterial, noise_seed = 0;
    Vec3f noise_offset;
};

// On the lowest terrain height under the footprint, sunk by 3% of the size.
float resting_height(const Terrain& t, float x, float z, float radius) {
    constexpr float d = 0.70710678f;
    constexpr float ring[8][2] = {{1, 0}, {d, d}, {0, 1}, {-d, d}, {-1, 0}, {-d, -d}, {0, -1}, {d, -d}};
    float lowest = t.height(x, z);
    for (const auto& r : ring) lowest = std::min(lowest, t.height(x + r[0] * radius, z + r[1] * radius));
    return lowest;
}

// In grid slot `slot` of a shape whose horizontal radius is `footprint` times its size.
CopyPlacement place_in_slot(const ScenePlan& plan, Rng& rng, uint64_t slot, float footprint) {
    const Terrain& t = plan.terrain;
    const float cell_x = float(t.extent / plan.grid_x), cell_z = float(t.extent / plan.grid_z);
    CopyPlacement c;
    c.size = std::min(0.5f * std::min(cell_x, cell_z), kMaxSizeOfExtent * float(t.extent)) * rng.uniform(0.65f, 1.0f);
    float radius = c.size * footprint;
    float jitter_x = std::max(0.0f, 0.5f * cell_x - radius), jitter_z = std::max(0.0f, 0.5f * cell_z - radius);
    c.x = float(-t.extent / 2) + cell_x * (float(slot % plan.grid_x) + 0.5f) + jitter_x * rng.uniform(-1, 1);
    c.z = float(-t.extent / 2) + cell_z * (float(slot / plan.grid_x) + 0.5f) + jitter_z * rng.uniform(-1, 1);
    c.base_y = resting_height(t, c.x, c.z, radius) - 0.03f * c.size;
    float u, v;
    do {
        u = rng.uniform(-1, 1), v = rng.uniform(-1, 1);
    } while (u * u + v * v > 1.0f || u * u + v * v < 0.01f);
    float inv = 1.0f / std::sqrt(u * u + v * v);
    c.cos_yaw = u * inv, c.sin_yaw = v * inv;
    c.material = kFirstStatueMaterial + uint32_t(rng.below(kMaterialCount - kFirstStatueMaterial));
    c.noise_seed = rng.bits32();
    c.noise_offset = {rng.uniform(0, 64), rng.uniform(0, 64), rng.uniform(0, 64)};
    return c;
}

CopyPlacement place_copy(const ScenePlan& plan, const GenerateOptions& options, uint64_t slot) {
    Rng rng(options.seed, Stream::Copy, slot);
    return place_in_slot(plan, rng, slot, plan.sources[plan.copies[slot].source].footprint);
}

// Level 0's vertices, then each level's midpoints: on the sphere for the
// blob, Phong-tessellation points (shape factor 3/4) for a statue.
void refine(StatueSource& s, uint32_t level, GeneratedObject& out) {
    out.positions = s.positions;
    out.normals = s.normals;
    for (uint32_t l = 1; l <= level; ++l) {
        for (auto [a, b] : s.level(l).midpoints) {
            Vec3f pa = out.positions[a], pb = out.positions[b], na = out.normals[a], nb = out.normals[b];
            Vec3f mid = (pa + pb) * 0.5f;
            if (s.spherical) {
                out.positions.push_back(normalize(mid));
                out.normals.push_back(out.positions.back());
                continue;
            }
            Vec3f on_a = mid - na * dot(mid - pa, na), on_b = mid - nb * dot(mid - pb, nb);
            out.positions.push_back(mid * 0.25f + (on_a + on_b) * 0.375f);
            out.normals.push_back(normalized_or_up(na + nb));
        }
    }
}

// A texture coordinate from the two axes across the normal's largest one.
Vec2f box_projection(Vec3f p, Vec3f n) {
    float ax = std::fabs(n.x), ay = std::fabs(n.y), az = std::fabs(n.z);
    Vec2f uv = ay >= ax && ay >= az ? Vec2f{p.x, p.z} : (ax >= az ? Vec2f{p.z, p.y} : Vec2f{p.x, p.y});
    return uv * 2.0f;
}

// The copy's own shape and displacement, in units of its size; returns the lowest y.
float displace(const StatueSource& s, const CopyPlacement& c, GeneratedObject& out) {
    float lowest = 1e30f;
    out.uvs.resize(out.positions.size());
    for (size_t v = 0; v < out.positions.size(); ++v) {
        Vec3f p = out.positions[v], n = out.normals[v];
        if (s.spherical) {
            Vec3f q = p * 1.2f + c.noise_offset;
            float shape = gradient_noise3(q, c.noise_seed + 7) + 0.5f * gradient_noise3(q * 2.0f, c.noise_seed + 8) +
                          0.25f * gradient_noise3(q * 4.0f, c.noise_seed + 9);
            p = p * (0.5f * (1.0f + kBlobShape * shape));
        }
        Vec3f q = p * 7.0f + c.noise_offset;
        float bump = gradient_noise3(q, c.noise_seed) + 0.5f * gradient_noise3(q * 2.1f, c.noise_seed + 1);
        p += n * (kDisplacement * bump);
        out.positions[v] = p;
        out.uvs[v] = box_projection(p, n);
        lowest = std::min(lowest, p.y);
    }
    return lowest;
}

void to_world(const CopyPlacement& c, float lowest, GeneratedObject& out) {
    for (Vec3f& p : out.positions) {
        Vec3f q{p.x * c.size, (p.y - lowest) * c.size, p.z * c.size};
        p = {c.x + c.cos_yaw * q.x + c.sin_yaw * q.z, c.base_y + q.y, c.z - c.sin_yaw * q.x + c.cos_yaw * q.z};
    }
}

// Prototype k of a forest, in its own space: size 1, standing on y = 0 at the origin.
void make_prototype(ScenePlan& plan, const GenerateOptions& options, uint32_t k, GeneratedObject& out) {
    const PlannedCopy& planned = plan.prototypes[k];
    StatueSource& source = plan.sources[planned.source];
    Rng rng(options.seed, Stream::Prototype, k);
    CopyPlacement shape;  // at the origin, size 1, unrotated
    shape.material = kFirstStatueMaterial + k % (kMaterialCount - kFirstStatueMaterial);
    shape.noise_seed = rng.bits32();
    shape.noise_offset = {rng.uniform(0, 64), rng.uniform(0, 64), rng.uniform(0, 64)};
    refine(source, planned.level, out);
    const float lowest = displace(source, shape, out);
    to_world(shape, lowest, out);
    out.indices = source.level(planned.level).indices;
    area_weighted_normals(out.positions, out.indices, out.normals);
    out.material_ids.assign(out.indices.size() / 3, shape.material);
}

// Placement `slot` of a forest: its prototype and world_from_object.
std::pair<uint32_t, Affine3f> place_instance(const ScenePlan& plan, const GenerateOptions& options, uint64_t slot) {
    Rng rng(options.seed, Stream::Placement, slot);
    const uint32_t k = uint32_t(rng.below(plan.prototypes.size()));
    const CopyPlacement c = place_in_slot(plan, rng, slot, plan.sources[plan.prototypes[k].source].footprint);
    Affine3f m;
    const float rows[3][4] = {{c.cos_yaw * c.size, 0, c.sin_yaw * c.size, c.x},
                              {0, c.size, 0, c.base_y},
                              {-c.sin_yaw * c.size, 0, c.cos_yaw * c.size, c.z}};
    std::memcpy(m.m, rows, sizeof(rows));
    return {k, m};
}

void make_statue_copy(ScenePlan& plan, const GenerateOptions& options, uint64_t slot, GeneratedObject& out) {
    const PlannedCopy& planned = plan.copies[slot];
    StatueSource& source = plan.sources[planned.source];
    CopyPlacement placement = place_copy(plan, options, slot);
    refine(source, planned.level, out);
    float lowest = displace(source, placement, out);
    to_world(placement, lowest, out);
    out.indices = source.level(planned.level).indices;
    area_weighted_normals(out.positions, out.indices, out.normals);
    out.material_ids.assign(out.indices.size() / 3, placement.material);
}

// ------------------------------------------------------------ emission

struct Workspace {
    GeneratedObject object, part;
    std::vector<uint32_t> remap, part_sources;
    std::vector<float> heights;
};

void clear(GeneratedObject& o) {
    o.positions.clear(), o.normals.clear(), o.uvs.clear(), o.indices.clear(), o.material_ids.clear();
}

// `whole` in consecutive triangle ranges of at most max_triangles, each with its own vertices.
void emit_in_parts(const GeneratedObject& whole, uint64_t max_triangles, Workspace& ws, const Sink& sink) {
    ws.remap.assign(whole.positions.size(), ~0u);
    const size_t triangles = whole.triangle_count();
    for (size_t first = 0; first < triangles; first += max_triangles) {
        clear(ws.part);
        ws.part_sources.clear();
        for (size_t t = first; t < std::min<size_t>(triangles, first + max_triangles); ++t) {
            for (size_t k = 3 * t; k < 3 * t + 3; ++k) {
                uint32_t v = whole.indices[k];
                if (ws.remap[v] == ~0u) {
                    ws.remap[v] = uint32_t(ws.part.positions.size());
                    ws.part_sources.push_back(v);
                    ws.part.positions.push_back(whole.positions[v]);
                    ws.part.normals.push_back(whole.normals[v]);
                    ws.part.uvs.push_back(whole.uvs[v]);
                }
                ws.part.indices.push_back(ws.remap[v]);
            }
            ws.part.material_ids.push_back(whole.material_ids[t]);
        }
        sink(ws.part);
        for (uint32_t v : ws.part_sources) ws.remap[v] = ~0u;
    }
}


// ------------------------------------------------------------ the look

constexpr int kTextureSize = 512;

// Tileable fBm over [0, 1)^2 (lattice periods 4, 8, ...); `ridged` sums
// absolute values, for veins.
float tileable_fbm(float u, float v, uint32_t seed, int octaves, bool ridged) {
    float sum = 0, amp = 0.5f;
    int32_t period = 4;
    for (int o = 0; o < octaves; ++o, amp *= 0.5f, period *= 2) {
        float n = gradient_noise2(u * float(period), v * float(period), seed + uint32_t(o), period);
        sum += amp * (ridged ? std::fabs(n) : n);
    }
    return sum;
}

uint8_t blend_byte(uint8_t a, uint8_t b, float t) {
    t = std::clamp(t, 0.0f, 1.0f);
    return uint8_t(float(a) + (float(b) - float(a)) * t + 0.5f);
}

// An RGBA8 sRGB texture blending two colours (given as sRGB bytes) by `blend(u, v)`.
template <class Blend>
Texture make_texture(const std::string& name, std::array<uint8_t, 3> a, std::array<uint8_t, 3> b, Blend blend) {
    Texture t;
    t.name = name;
    t.width = t.height = kTextureSize;
    t.channels = 4;
    t.texels8.resize(size_t(kTextureSize) * kTextureSize * 4);
    for (int y = 0; y < kTextureSize; ++y) {
        for (int x = 0; x < kTextureSize; ++x) {
            float w = blend((float(x) + 0.5f) / kTextureSize, (float(y) + 0.5f) / kTextureSize);
            uint8_t* texel = &t.texels8[(size_t(y) * kTextureSize + x) * 4];
            for (int c = 0; c < 3; ++c) texel[c] = blend_byte(a[c], b[c], w);
            texel[3] = 255;
        }
    }
    return t;
}

std::vector<Texture> make_textures(uint64_t seed) {
    Rng rng(seed, Stream::Texture);
    uint32_t ground_seed = rng.bits32(), stone_seed = rng.bits32();
    Texture ground = make_texture("generated:ground", {74, 92, 40}, {120, 98, 66}, [&](float u, float v) {
        return 0.5f + 1.2f * tileable_fbm(u, v, ground_seed, 7, false);
    });
    Texture stone = make_texture("generated:stone", {206, 200, 190}, {112, 108, 102}, [&](float u, float v) {
        return 1.0f - 2.2f * tileable_fbm(u, v, stone_seed, 6, true);
    });
    return {std::move(ground), std::move(stone)};
}

Material make_material(const std::string& name, Vec3f color, float roughness, float metallic = 0,
                       int32_t texture = kNoTexture) {
    Material m;
    m.name = name;
    m.base_color = color;
    m.roughness = roughness;
    m.metallic = metallic;
    m.base_color_texture = texture;
    return m;
}

// Indexed by kTerrainMaterial, kRockMaterial, then the statues' palette.
std::vector<Material> make_materials() {
    std::vector<Material> m = {
        make_material("terrain", {1, 1, 1}, 0.95f, 0, 0),
        make_material("rock", {0.85f, 0.82f, 0.78f}, 0.85f, 0, 1),
        make_material("stone", {1, 1, 1}, 0.6f, 0, 1),
        make_material("marble", {0.9f, 0.88f, 0.85f}, 0.15f),
        make_material("bronze", {0.72f, 0.45f, 0.2f}, 0.3f, 1),
        make_material("terracotta", {0.62f, 0.25f, 0.14f}, 0.8f),
        make_material("jade", {0.25f, 0.55f, 0.38f}, 0.25f),
        make_material("gold", {0.95f, 0.7f, 0.3f}, 0.2f, 1),
    };
    m[0].specular = 0.3f;
    return m;
}

// From one corner (outside every statue's cell), a little above the hills,
// along the diagonal at a point at most about 200 m away, so that on large
// terrains the nearest statues still fill the view.
Camera make_camera(const Terrain& t) {
    float w = float(t.extent);
    float reach = std::min(0.4f * w, 150.0f);
    float eye_xz = -0.5f * w, target_xz = eye_xz + reach;
    float ground = std::max(t.height(eye_xz, eye_xz), t.height(target_xz, target_xz));
    Camera camera;
    camera.eye = {eye_xz, ground + 0.12f * reach + 1.0f, eye_xz};
    camera.target = {target_xz, t.height(target_xz, target_xz) + 0.04f * reach, target_xz};
    camera.vfov_degrees = 45.0f;
    return camera;
}

Box3f scene_bounds(const Terrain& t) {
    float half = float(t.extent / 2) * 1.01f, w = float(t.extent);
    float max_statue = kMaxSizeOfExtent * w;
    // A blob reaches 1.5 of its size in height; copies sink 3% of it.
    return {{-half, -t.height_bound() - 0.05f * max_statue, -half},
            {half, t.height_bound() + 1.55f * max_statue, half}};
}

}  // namespace

// The forest's prototypes, then its placements: through `instances`, or as
// world-space copies to `sink` (every copy then counts as emitted).
template <class Report>
void emit_forest(ScenePlan& plan, const GenerateOptions& options, const Sink& sink, const InstanceSink* instances,
                 Workspace& ws, uint64_t& emitted, const Report& report) {
    std::vector<uint32_t> ids(plan.prototypes.size());
    std::vector<GeneratedObject> copies(instances ? 0 : plan.prototypes.size());
    for (uint32_t k = 0; k < plan.prototypes.size(); ++k) {
        clear(ws.object);
        make_prototype(plan, options, k, ws.object);
        if (instances) {
            ids[k] = instances->prototype(ws.object);
            emitted += ws.object.triangle_count();
        } else {
            copies[k] = ws.object;
        }
    }
    for (uint64_t slot = 0; slot < plan.placements; ++slot) {
        const auto [k, m] = place_instance(plan, options, slot);
        if (instances) {
            instances->place(ids[k], m);
        } else {
            ws.object = copies[k];
            for (Vec3f& p : ws.object.positions) p = m.transform_point(p);
            for (Vec3f& n : ws.object.normals) n = normalized_or_up(m.normal_matrix().transform_vector(n));
            sink(ws.object);
            emitted += ws.object.triangle_count();
        }
    }
    report(1.0);
}

std::vector<std::string> generator_names() { return {"terrain-statues", "terrain", "forest"}; }

GeneratedLook generated_look(const GenerateOptions& options) {
    check_options(options);
    Terrain terrain = terrain_shape(options);
    GeneratedLook look;
    look.materials = make_materials();
    look.textures = make_textures(options.seed);
    look.camera = make_camera(terrain);
    Light sun;
    sun.type = LightType::Directional;
    sun.direction = normalize(Vec3f{-0.5f, -0.75f, -0.3f});
    sun.color = {1.0f, 0.95f, 0.86f};
    sun.intensity = 3.0f;
    look.lights = {sun};
    look.environment.color = {0.5f, 0.65f, 0.9f};
    look.bounds = scene_bounds(terrain);
    return look;
}

uint64_t generate_scene(const GenerateOptions& options, const Sink& sink,
                        const std::function<void(double)>& progress, const InstanceSink* instances) {
    check_options(options);
    ScenePlan plan = plan_scene(options);
    Workspace ws;
    uint64_t emitted = 0;
    auto report = [&](double fraction) {
        if (progress) progress(fraction);
    };
    report(0.0);
    const Terrain& t = plan.terrain;
    for (uint32_t j0 = 0; j0 < t.cells_z; j0 += t.tile_cells) {
        for (uint32_t i0 = 0; i0 < t.cells_x; i0 += t.tile_cells) {
            clear(ws.object);
            make_terrain_tile(t, i0, j0, ws.object, ws.heights);
            sink(ws.object);
            emitted += ws.object.triangle_count();
            report(double(emitted) / double(plan.triangles));
        }
    }
    for (uint64_t slot = 0; slot < plan.copies.size(); ++slot) {
        make_statue_copy(plan, options, slot, ws.object);
        if (ws.object.triangle_count() > options.max_object_triangles)
            emit_in_parts(ws.object, options.max_object_triangles, ws, sink);
        else
            sink(ws.object);
        emitted += ws.object.triangle_count();
        report(double(emitted) / double(plan.triangles));
    }
    if (!plan.prototypes.empty()) emit_forest(plan, options, sink, instances, ws, emitted, report);
    report(1.0);
    return emitted;
}

}  // namespace rf::pack
