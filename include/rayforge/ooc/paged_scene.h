// Paged scenes: scenes far larger than memory, traced and rendered from a
// budgeted page cache (Garanzha 2014, ch. 6, "OOC-IRT"; docs/paged-scenes.md).
// A paged scene file (.rfpack) is written once, by converting a scene
// (convert_to_paged) or by generating one (generate_paged_scene); opening it
// reads only the always-resident levels (page bounds, the top grid, the
// middle BVHs, materials and lights). Geometry pages, surface attributes and
// texture tiles are then read on demand by three page managers, each
// bounded by its budget.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/core/progress.h"
#include "rayforge/math/box.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/light.h"
#include "rayforge/scene/scene.h"

namespace rf {

// ---- Writing -------------------------------------------------------------

// How rays find the pages they meet (the file's always-resident top level).
enum class PagedTopLevel {
    WideBvh,  // one compressed 8-wide BVH over the pages' bounds (the default: fewest node visits)
    Grid,     // Garanzha 2014's top grid with a BVH over the clipped page bounds in every cell (§6.3.1)
};

// "bvh" / "grid"; rf::Error for any other name.
PagedTopLevel parse_paged_top_level(const std::string& name);
std::string to_string(PagedTopLevel top);

// How pages are stored (each kept raw where the codec does not make it smaller).
enum class PagedCodec {
    Meshopt,  // meshoptimizer's vertex/index codecs over the pages' records, then zstd (the default: smallest)
    Zstd,     // zstd alone
    None,     // raw
};
// "meshopt" / "zstd" / "none"; rf::Error for any other name.
PagedCodec parse_paged_codec(const std::string& name);
std::string to_string(PagedCodec codec);

// How surface attributes (shading normals, uvs, materials, tangents) are stored.
enum class PagedAttributes {
    Shared,   // per-vertex data shared within a page, per-triangle data once (the default: exact but for an
              // octahedral geometric normal, about a third of Full's bytes)
    Full,     // a 64-byte record a triangle, exact
    Compact,  // a 32-byte record a triangle (half-float uvs; no normal-map tangents, no uv-density mip selection)
};
// "shared" / "full" / "compact"; rf::Error for any other name.
PagedAttributes parse_paged_attributes(const std::string& name);
std::string to_string(PagedAttributes attributes);

struct PagedWriteOptions {
    PagedCodec codec = PagedCodec::Meshopt;
    int zstd_level = 3;                  // 1..19 (Meshopt and Zstd)
    PagedAttributes attributes = PagedAttributes::Shared;
    uint32_t attribute_page_bytes = 8192;  // a power of two, 1 KB .. 1 MB (a page holds at most this much, raw)
    uint32_t quads_per_page = 4096;        // 64 .. 4096 (Garanzha 2014's NP = 4K)
    PagedTopLevel top_level = PagedTopLevel::WideBvh;
    // A mesh placed by several instances is written once and placed by
    // instances (the seed's clones); true writes every instance's triangles
    // in world space instead (the seed's unique-geometry files).
    bool flatten_instances = false;
    int grid_resolution = 32;              // PagedTopLevel::Grid: cells on the longest axis, 1 .. 256 (Garanzha 2014's 32^3)
    int threads = 0;                       // 0 = all cores
};

struct PagedWriteReport {
    uint64_t triangles = 0, quads = 0, paired_triangles = 0;  // unique: every page's once
    uint64_t instances = 0, instanced_triangles = 0;           // placements, and the triangles they place
    uint32_t geometry_pages = 0, attribute_pages = 0, texture_pages = 0;
    uint32_t middle_nodes = 0;  // PagedTopLevel::Grid: the cells' BVH nodes
    uint32_t top_nodes = 0;     // PagedTopLevel::WideBvh: the top BVH's nodes
    uint64_t file_bytes = 0, geometry_bytes = 0, attribute_bytes = 0, texture_bytes = 0, resident_bytes = 0;
    uint64_t decoded_bytes = 0;           // every page as decoded: what caching the whole scene takes
    double max_quantisation_error = 0.0;  // largest |decoded - input| vertex coordinate, world units
    std::vector<std::string> notes;       // what the paged form leaves out (opaque cut-outs, ...)
    // convert_file_to_paged only:
    bool streamed = false;                // the input was streamed (OBJ), not loaded in core
    uint64_t objects = 0;                 // objects handed to the writer when streamed
    uint64_t scratch_bytes = 0;           // the streaming converter's scratch files, together
    uint64_t max_object_triangles = 0;    // the largest object its memory budget allowed
    // The file's density: file bytes / unique triangles.
    [[nodiscard]] double bytes_per_triangle() const { return triangles ? double(file_bytes) / double(triangles) : 0.0; }
};

// Writes `scene` (finalize()d) as a paged scene file, instance by instance.
PagedWriteReport convert_to_paged(const Scene& scene, const std::string& path, const PagedWriteOptions& options = {},
                                  const ProgressCallback& progress = {});

// How convert_file_to_paged reads its input.
struct ConvertInputOptions {
    uint64_t memory_budget = uint64_t(1) << 30;  // the streaming converter's working memory, >= 96 MiB
    std::string temp_dir;                        // its scratch files (unlinked at once); "" = the output's folder
};
// Converts a scene file. OBJ input is streamed: read in blocks, its arrays
// spilled to scratch files, the triangles cut into spatially compact objects
// that fit `input.memory_budget`, so a file larger than memory converts.
// Other formats (and builtin:NAME) are loaded in core first (a note says so).
PagedWriteReport convert_file_to_paged(const std::string& scene_file, const std::string& path,
                                       const PagedWriteOptions& options = {}, const ConvertInputOptions& input = {},
                                       const ProgressCallback& progress = {});

struct GenerateOptions {
    std::string name = "terrain-statues";  // generated_scene_names()
    uint64_t triangles = 4'000'000;
    uint64_t seed = 1;
    std::string statue_dir;               // a folder with stanford-bunny/ and stanford-dragon/; else procedural statues
    uint64_t max_object_triangles = 2'000'000;
    uint64_t instanced_triangles = 0;  // "forest": the triangles its instances show (0: 25 x triangles)
};
std::vector<std::string> generated_scene_names();
// A procedural scene of unique geometry, written straight into a paged
// file (out of core: one object at a time), or into an OBJ file when `path`
// ends in .obj. Deterministic from options.seed.
PagedWriteReport generate_paged_scene(const GenerateOptions& options, const std::string& path,
                                      const PagedWriteOptions& write = {}, const ProgressCallback& progress = {});
// The same scene in memory (for small sizes: tests and in-core comparisons).
Scene generate_scene(const GenerateOptions& options);

// ---- Reading -------------------------------------------------------------

struct PagedSceneOptions {
    size_t memory_budget = size_t(1) << 30;  // the page caches together
    // Per-manager budgets; 0 takes a share of memory_budget: geometry 70%,
    // attributes 15%, textures 15% (without textures 80% and 20%). A share
    // larger than its manager can use (all its pages at once) passes the
    // rest to the other shares. Opening fails with rf::Error when the caches
    // could grow past the memory available (rf::memory_budget()).
    size_t geometry_budget = 0;
    size_t attribute_budget = 0;
    size_t texture_budget = 0;
    int threads = 0;  // 0 = all cores
    // Rendering: paths (or pixels) traced as one batch of query loops; larger
    // batches amortise page loads (Garanzha 2014: up to 16M rays) and cost about
    // 250 bytes a path. 1024 .. 16M.
    uint32_t batch_paths = 1u << 18;
};

// One page manager's state and counts since the last reset.
struct PageCacheReport {
    std::string name;                 // geometry, attributes, textures
    uint32_t pages = 0, slots = 0, cached = 0;
    size_t slot_bytes = 0, budget_bytes = 0, memory_bytes = 0;
    uint64_t requests = 0, hits = 0, misses = 0, pages_read = 0, bytes_read = 0, evictions = 0, swaps = 0;
    double io_ms = 0.0, manage_ms = 0.0;
    [[nodiscard]] double hit_rate() const { return requests ? double(hits) / double(requests) : 1.0; }
};

struct PagedSceneInfo {
    std::string path;
    uint64_t triangles = 0, quads = 0, file_bytes = 0;  // triangles: unique (every page's once)
    uint64_t instances = 0, instanced_triangles = 0;     // placements, and the triangles they place
    uint32_t geometry_pages = 0, attribute_pages = 0, texture_pages = 0;
    uint32_t materials = 0, lights = 0, textures = 0, objects = 0;
    PagedTopLevel top_level = PagedTopLevel::WideBvh;
    uint32_t top_nodes = 0;          // WideBvh: nodes of the top BVH
    int grid[3] = {1, 1, 1};         // Grid: cells per axis
    Box3f bounds;
    size_t resident_bytes = 0;      // always in memory: the resident levels, tables, directory
    PagedAttributes attributes = PagedAttributes::Shared;
    uint32_t attribute_page_bytes = 0;
    uint64_t meshopt_pages = 0, zstd_pages = 0, raw_pages = 0;  // pages as stored, by codec
    uint64_t decoded_bytes = 0;      // every page as decoded: what caching the whole scene takes
    std::string page_reads;          // how pages are read: "io_uring (queue depth 64)" or "reader pool (...): why"
    // The file's density: file bytes / unique triangles.
    [[nodiscard]] double bytes_per_triangle() const { return triangles ? double(file_bytes) / double(triangles) : 0.0; }
};

// What the query loops did since the last reset.
struct PagedQueryStats {
    uint64_t queries = 0, iterations = 0, ray_iterations = 0, shading_fetches = 0;
    // cells: top-grid cells walked (Grid files); middle_nodes: top-level nodes
    // visited (the cells' binary BVH nodes, or the top BVH's wide nodes).
    uint64_t cells = 0, middle_nodes = 0, pages_searched = 0, page_nodes = 0, quads_tested = 0;
    double traversal_ms = 0.0, sort_ms = 0.0;
};

class PagedScene {
public:
    virtual ~PagedScene() = default;
    [[nodiscard]] virtual const PagedSceneInfo& info() const = 0;
    [[nodiscard]] virtual Camera camera() const = 0;  // the file's camera
    [[nodiscard]] virtual std::vector<Light> lights() const = 0;  // the file's lights
    [[nodiscard]] virtual Environment environment() const = 0;    // the file's environment
    // Ray queries through the geometry cache (batches run the re-entrant
    // query loop; a single ray is a batch of one). Hit::prim identifies a
    // paged triangle (page * 8192 + slot), not an input triangle.
    [[nodiscard]] virtual const Accel& accel() const = 0;
    // accel().intersect, and each hit's instance in the file (0xFFFFFFFF for
    // a world-space page or a miss): instanced meshes are paged once and
    // placed by instances, so a paged triangle id alone does not say where.
    virtual void intersect(std::span<const Ray> rays, std::span<Hit> hits, std::span<uint32_t> instances) const = 0;
    [[nodiscard]] virtual std::vector<PageCacheReport> caches() const = 0;
    [[nodiscard]] virtual PagedQueryStats query_stats() const = 0;
    virtual void reset_stats() = 0;
    // Empties the caches (a cold start); with `os_cache`, also asks the
    // operating system to drop the file's pages from its own cache
    // (posix_fadvise DONTNEED), so the next reads come from the disk.
    virtual void clear_caches(bool os_cache = false) = 0;
    // The caches plus the resident levels: what this scene holds in memory.
    [[nodiscard]] virtual size_t memory_bytes() const = 0;
};

// True when `path` starts like a paged scene file.
bool is_paged_scene_file(const std::string& path);
// Opens and checks a paged scene file; rf::Error for a missing, truncated or
// corrupted file or budgets that hold no page.
std::unique_ptr<PagedScene> open_paged_scene(const std::string& path, const PagedSceneOptions& options = {});

// Every page of a paged file decoded into world-space triangles, once for
// a world-space page and once per instance for an instanced object's page,
// in page order (triangle i of the result is paged triangle page * 8192 +
// slot, listed in `prims`, through instance `instances[i]`): the same
// quantised geometry in core, for comparisons (needs memory for the whole
// scene, instances expanded). Degenerate halves of unpaired quads are left out.
struct DecodedPagedGeometry {
    SceneGeometry geometry;
    std::vector<uint32_t> prims;      // paged primitive id of each triangle
    std::vector<uint32_t> instances;  // its instance (0xFFFFFFFF: a world-space page)
};
DecodedPagedGeometry decode_paged_geometry(const std::string& path);

}  // namespace rf
