// The public face of paged scenes (rayforge/ooc/paged_scene.h): an opened
// file with its page managers and its query engine behind rf::Accel.
#include "rayforge/ooc/paged_scene.h"

#include <algorithm>
#include <cstring>

#include "ooc/paged_scene_impl.h"
#include "ooc/uring_reader.h"
#include "ooc/page_cache.h"
#include "ooc/texture_cache.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {

namespace pack {

namespace {

PageCacheReport report(const std::string& name, const PageCacheStats& s, uint32_t pages, uint32_t slots,
                       uint32_t cached, size_t slot_bytes, size_t budget, size_t memory) {
    PageCacheReport r;
    r.name = name;
    r.pages = pages;
    r.slots = slots;
    r.cached = cached;
    r.slot_bytes = slot_bytes;
    r.budget_bytes = budget;
    r.memory_bytes = memory;
    r.requests = s.requests;
    r.hits = s.hits;
    r.misses = s.misses;
    r.pages_read = s.pages_read;
    r.bytes_read = s.bytes_read;
    r.evictions = s.evictions;
    r.swaps = s.swaps;
    r.io_ms = s.io_ms;
    r.manage_ms = s.manage_ms;
    return r;
}

// The options' budgets: the ones given as they are; the others shares of the
// total (geometry 70 %, attributes 15 %, textures 15 %; without textures
// 80 % and 20 %), where a share larger than its manager can use (every page
// of its kind held at once) gives the rest to the other shares that can
// use it, in proportion to their weights.
struct Budgets {
    size_t geometry, attributes, textures;
};

Budgets split_budget(const PagedSceneOptions& o, const PackFile& file) {
    const FileHeader& h = file.header();
    const bool has_textures = h.texture_pages > 0;
    const double weight[3] = {has_textures ? 0.70 : 0.80, has_textures ? 0.15 : 0.20, has_textures ? 0.15 : 0.0};
    const size_t given[3] = {o.geometry_budget, o.attribute_budget, has_textures ? o.texture_budget : 0};
    const double need[3] = {
        double(PageCache::budget_for_all(h.geometry_pages, largest_raw_page(file, 0, h.geometry_pages))),
        double(PageCache::budget_for_all(h.attribute_pages, file.resident().attribute_page_bytes)),
        double(TextureTileCache::budget_for_slots(h.texture_pages))};
    double share[3];
    bool open[3];  // a default share that can take more
    for (int m = 0; m < 3; ++m) {
        share[m] = given[m] ? double(given[m]) : double(o.memory_budget) * weight[m];
        open[m] = !given[m] && weight[m] > 0.0;
    }
    for (int round = 0; round < 3; ++round) {  // each round closes at least one share, or ends
        double surplus = 0.0, open_weight = 0.0;
        for (int m = 0; m < 3; ++m) {
            if (!open[m]) continue;
            if (share[m] >= need[m]) {
                surplus += share[m] - need[m];
                share[m] = need[m];
                open[m] = false;
            } else {
                open_weight += weight[m];
            }
        }
        if (surplus <= 0.0 || open_weight <= 0.0) break;
        for (int m = 0; m < 3; ++m)
            if (open[m]) share[m] += surplus * weight[m] / open_weight;
    }
    return {size_t(share[0]), size_t(share[1]), has_textures ? size_t(share[2]) : 0};
}

// rf::Error when the caches could grow past the process's memory budget
// (MemAvailable, or RAYFORGE_MEMORY_BUDGET): a budget the machine cannot
// hold fails here with its numbers, not later to the OOM killer.
void check_against_memory(const Budgets& b, const PackFile& file, const std::string& path) {
    const FileHeader& h = file.header();
    const uint64_t reach =
        std::min<uint64_t>(b.geometry, PageCache::budget_for_all(h.geometry_pages, largest_raw_page(file, 0, h.geometry_pages))) +
        std::min<uint64_t>(b.attributes, PageCache::budget_for_all(h.attribute_pages, file.resident().attribute_page_bytes)) +
        std::min<uint64_t>(b.textures, TextureTileCache::budget_for_slots(h.texture_pages)) +
        file.resident_memory_bytes();
    if (reach > memory_budget()) {
        throw Error(path + ": the page caches and resident levels may grow to " + std::to_string(reach >> 20) +
                    " MiB, more than the " + std::to_string(memory_budget() >> 20) +
                    " MiB of memory available (MemAvailable, or RAYFORGE_MEMORY_BUDGET): give a smaller --memory-budget");
    }
}

}  // namespace

PagedAccel::PagedAccel(PagedEngine& engine) : engine_(engine) {}

Hit PagedAccel::intersect(const Ray& ray) const {
    Hit hit;
    engine_.intersect(std::span<const Ray>(&ray, 1), std::span<Hit>(&hit, 1));
    return hit;
}

bool PagedAccel::occluded(const Ray& ray) const {
    uint8_t blocked = 0;
    engine_.occluded(std::span<const Ray>(&ray, 1), std::span<uint8_t>(&blocked, 1));
    return blocked != 0;
}

void PagedAccel::intersect(std::span<const Ray> rays, std::span<Hit> hits) const { engine_.intersect(rays, hits); }

void PagedAccel::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    engine_.occluded(rays, occluded);
}

AccelStats PagedAccel::stats() const {
    const PackFile& f = engine_.file();
    AccelStats s;
    const bool grid = f.resident().top_level == TopLevel::Grid;
    s.name = grid ? "paged/grid+bvh" : "paged/bvh";
    s.node_count = grid ? f.middle_nodes().size() : f.top_nodes().size();
    s.leaf_count = f.pages().size();
    s.bytes = f.resident_memory_bytes();
    s.sah_cost = s.quality_cost = std::nan("");
    return s;
}

PagedSceneImpl::PagedSceneImpl(const std::string& path, const PagedSceneOptions& options)
    : file_(std::make_shared<const PackFile>(path)), batch_paths_(options.batch_paths) {
    const Budgets budgets = split_budget(options, *file_);
    check_against_memory(budgets, *file_, path);
    engine_ = std::make_unique<PagedEngine>(file_, EngineBudgets{budgets.geometry, budgets.attributes}, options.threads);
    textures_ = std::make_unique<TextureTileCache>(*file_, budgets.textures, "textures");
    paged_textures_ = make_paged_textures(*file_, *textures_);
    accel_ = std::make_unique<PagedAccel>(*engine_);
    budgets_[0] = budgets.geometry;
    budgets_[1] = budgets.attributes;
    budgets_[2] = budgets.textures;
    fill_info(path);
}

void PagedSceneImpl::fill_info(const std::string& path) {
    const FileHeader& h = file_->header();
    const ResidentHeader& r = file_->resident();
    info_.path = path;
    info_.triangles = h.triangle_count;
    info_.quads = h.quad_count;
    info_.file_bytes = h.file_bytes;
    info_.geometry_pages = h.geometry_pages;
    info_.attribute_pages = h.attribute_pages;
    info_.texture_pages = h.texture_pages;
    info_.materials = r.material_count;
    info_.lights = r.light_count;
    info_.textures = r.texture_count;
    info_.objects = r.object_count;
    for (int a = 0; a < 3; ++a) info_.grid[a] = r.grid_res[a];
    info_.top_level = r.top_level == pack::TopLevel::Grid ? PagedTopLevel::Grid : PagedTopLevel::WideBvh;
    info_.top_nodes = r.top_node_count;
    info_.instances = r.instance_count;
    info_.instanced_triangles = uint64_t(r.instanced_triangles[0]) | uint64_t(r.instanced_triangles[1]) << 32;
    info_.bounds = r.bounds;
    info_.resident_bytes = file_->resident_memory_bytes();
    info_.attributes = r.attribute_format == AttributeFormat::Shared ? PagedAttributes::Shared
                       : r.attribute_format == AttributeFormat::Full ? PagedAttributes::Full
                                                                     : PagedAttributes::Compact;
    info_.attribute_page_bytes = r.attribute_page_bytes;
    info_.page_reads = UringReader::describe();
    for (const PageEntry& e : file_->directory()) {
        ++(e.codec == Codec::Meshopt ? info_.meshopt_pages : e.codec == Codec::Zstd ? info_.zstd_pages : info_.raw_pages);
        info_.decoded_bytes += e.raw_bytes;
    }
}

Camera PagedSceneImpl::camera() const {
    if (file_->has_camera()) return file_->camera();
    Scene empty;
    return empty.camera_or_default();
}

std::vector<PageCacheReport> PagedSceneImpl::caches() const {
    const PageCache& g = engine_->geometry_cache();
    const PageCache& a = engine_->attribute_cache();
    const TextureTileCache& t = *textures_;
    return {report(g.name(), g.stats(), g.page_count(), g.slot_count(), g.cached_count(), g.slot_bytes(), budgets_[0],
                   g.memory_bytes()),
            report(a.name(), a.stats(), a.page_count(), a.slot_count(), a.cached_count(), a.slot_bytes(), budgets_[1],
                   a.memory_bytes()),
            report(t.name(), t.stats(), t.page_count(), t.slot_count(), t.cached_count(), TextureTileCache::kTileBytes,
                   budgets_[2], t.memory_bytes())};
}

PagedQueryStats PagedSceneImpl::query_stats() const {
    const EngineStats& e = engine_->stats();
    PagedQueryStats q;
    q.queries = e.queries;
    q.iterations = e.iterations;
    q.ray_iterations = e.ray_iterations;
    q.shading_fetches = e.shading_fetches;
    q.cells = e.cells;
    q.middle_nodes = e.middle;
    q.pages_searched = e.pages;
    q.page_nodes = e.nodes;
    q.quads_tested = e.quads;
    q.traversal_ms = e.traversal_ms;
    q.sort_ms = e.sort_ms;
    return q;
}

void PagedSceneImpl::reset_stats() {
    engine_->reset_stats();
    textures_->reset_stats();
}

void PagedSceneImpl::clear_caches(bool os_cache) {
    engine_->geometry_cache().clear();
    engine_->attribute_cache().clear();
    textures_->clear();
    if (os_cache) file_->drop_os_cache();
}

size_t PagedSceneImpl::memory_bytes() const {
    return engine_->memory_bytes() + textures_->memory_bytes();
}

}  // namespace pack

std::unique_ptr<PagedScene> open_paged_scene(const std::string& path, const PagedSceneOptions& options) {
    if (options.memory_budget == 0 && (!options.geometry_budget || !options.attribute_budget))
        throw Error("paged scene: the memory budget must be positive");
    if (options.batch_paths < 1024 || options.batch_paths > (16u << 20))
        throw Error("paged scene: the batch must hold 1024 to 16M paths, got " + std::to_string(options.batch_paths));
    return std::make_unique<pack::PagedSceneImpl>(path, options);
}

}  // namespace rf

namespace rf {

DecodedPagedGeometry decode_paged_geometry(const std::string& path) {
    const pack::PackFile file(path);
    DecodedPagedGeometry out;
    SceneGeometry& g = out.geometry;
    // The instances of each page (none: the page lies in world space).
    std::vector<std::vector<uint32_t>> instances_of(file.header().geometry_pages);
    for (uint32_t i = 0; i < file.instances().size(); ++i) {
        const pack::InstanceInfo& inst = file.instances()[i];
        for (uint32_t p = inst.first_page; p < inst.first_page + inst.page_count; ++p) instances_of[p].push_back(i);
    }
    std::vector<uint8_t> bytes, scratch;
    for (uint32_t p = 0; p < file.header().geometry_pages; ++p) {
        const pack::PageInfo& info = file.pages()[p];
        if (info.instanced && instances_of[p].empty()) continue;  // an object no instance places
        file.read_page(p, bytes, scratch);
        const pack::GeometryPageView page = pack::view_geometry_page(bytes, path);
        const std::vector<uint32_t> placements = info.instanced ? instances_of[p] : std::vector<uint32_t>{pack::kNoInstance};
        for (uint32_t instance : placements) {
            Affine3f to_world = Affine3f::identity();
            if (instance != pack::kNoInstance)
                std::memcpy(to_world.m, file.instances()[instance].world_from_object, sizeof(to_world.m));
            for (uint32_t q = 0; q < page.quad_count; ++q) {
                const auto& v = page.quads[q].v;
                for (int half = 0; half < 2; ++half) {
                    if (half == 1 && std::memcmp(v[3], v[0], sizeof(v[0])) == 0) continue;
                    const int c = half == 0 ? 1 : 2, d = half == 0 ? 2 : 3;
                    const auto decode = [&](const int16_t* q3) {
                        return to_world.transform_point(info.offset +
                                                        info.scale * Vec3f(float(q3[0]), float(q3[1]), float(q3[2])));
                    };
                    g.triangles.push_back({decode(v[0]), decode(v[c]), decode(v[d])});
                    g.bounds.extend(g.triangles.back().bounds());
                    g.triangle_instance.push_back(0);
                    g.local_triangle.push_back(uint32_t(out.prims.size()));
                    g.material.push_back(0);
                    out.prims.push_back(p * pack::kTrianglesPerPageSlot + 2 * q + uint32_t(half));
                    out.instances.push_back(instance);
                }
            }
        }
    }
    g.normal_matrices.push_back(Affine3f::identity());
    return out;
}

}  // namespace rf
