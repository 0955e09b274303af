#include "ooc/paged_engine.h"

#include <algorithm>
#include <chrono>

#include "backend/cpu/cpu_wavefront.h"
#include "core/parallel.h"
#include "ooc/device_page_cache_steps.h"
#include "ooc/attribute_records.h"
#include "ooc/shared_attributes.h"
#include "rayforge/core/error.h"
#include "render/ray_sort_key.h"

namespace rf::pack {

namespace {

using Clock = std::chrono::steady_clock;
constexpr uint32_t kRayGrain = 256;  // rays per task: a coherent block of the sorted batch

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

PagedEngine::PagedEngine(std::shared_ptr<const PackFile> file, const EngineBudgets& budgets, int threads)
    : file_(std::move(file)), threads_(threads) {
    const FileHeader& h = file_->header();
    geometry_ = std::make_unique<PageCache>(*file_, 0, h.geometry_pages, largest_raw_page(*file_, 0, h.geometry_pages),
                                            budgets.geometry, "geometry");
    attributes_ = std::make_unique<PageCache>(*file_, file_->first_attribute_page(), h.attribute_pages,
                                              file_->resident().attribute_page_bytes, budgets.attributes, "attributes");
}

PagedSceneView PagedEngine::view() {
    const PackFile& f = *file_;
    return make_paged_view(f,
                           {f.pages().data(), f.page_roots().data(), f.cell_roots().data(), f.middle_nodes().data(), f.top_nodes().data(),
                            f.top_refs().data(), f.instances().data()},
                           geometry_->view());
}

void PagedEngine::reset_stats() {
    stats_ = {};
    geometry_->reset_stats();
    attributes_->reset_stats();
}

size_t PagedEngine::memory_bytes() const {
    return file_->resident_memory_bytes() + geometry_->memory_bytes() + attributes_->memory_bytes();
}

template <bool kAnyHit>
void PagedEngine::run_queries(std::span<const Ray> rays, std::span<PagedRayState> states) {
    const uint32_t n = uint32_t(rays.size());
    const PagedSceneView v = view();
    Clock::time_point start = Clock::now();
    // Coherent order: by the rays' keys over the scene's bounds.
    order_.resize(n);
    keys_.resize(n);
    const Box3f bounds = file_->resident().bounds;
    parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t i = lo; i < hi; ++i) {
            order_[i] = i;
            keys_[i] = ray_sort_key(rays[i], bounds);
        }
    });
    sort_queue_by_key(order_, keys_);
    stats_.sort_ms += ms_since(start);

    geometry_->clear_was_read();
    pending_ = order_;
    std::vector<uint8_t> again(n);
    // WasRead survives eviction, so a page is loaded at most once per loop:
    // more iterations than pages would mean a bug, not a slow scene.
    const uint64_t iteration_limit = uint64_t(file_->header().geometry_pages) + 2;
    for (uint64_t iteration = 0; !pending_.empty(); ++iteration) {
        if (iteration > iteration_limit)
            throw Error(file_->path() + ": paged query loop did not converge (a page manager bug)");
        start = Clock::now();
        const uint32_t count = uint32_t(pending_.size());
        // The first iteration (fresh rays) and after a large swap, every ray runs.
        const std::span<const uint32_t> last_loaded = geometry_->last_loaded();
        const FreshPages fresh = iteration > 0 && last_loaded.size() <= kMaxFreshPages
                                     ? FreshPages{last_loaded.data(), uint32_t(last_loaded.size())}
                                     : FreshPages{};
        std::mutex totals_mutex;
        parallel::for_range(0u, count, kRayGrain, [&](uint32_t lo, uint32_t hi) {
            PagedCounters c;
            for (uint32_t k = lo; k < hi; ++k) {
                const uint32_t i = pending_[k];
                again[k] = paged_iteration<kAnyHit>(v, rays[i], states[i], c, fresh) ? 1 : 0;
            }
            std::lock_guard<std::mutex> lock(totals_mutex);
            stats_.add(c);
        });
        ++stats_.iterations;
        uint32_t kept = 0;
        for (uint32_t k = 0; k < count; ++k)
            if (again[k]) pending_[kept++] = pending_[k];
        pending_.resize(kept);
        stats_.traversal_ms += ms_since(start);
        geometry_->mark_cached_as_read();
        // Also counts the uses of cached pages when nothing is missing.
        const size_t loaded = geometry_->swap_requested_pages();
        if (pending_.empty()) break;
        if (loaded == 0)
            throw Error(file_->path() + ": paged query loop made no progress (page manager loaded nothing)");
    }
    stats_.queries += n;
}

void PagedEngine::intersect(std::span<const Ray> rays, std::span<Hit> hits, std::span<uint32_t> instances) {
    std::lock_guard<std::mutex> lock(mutex_);
    parallel::with_threads(threads_, [&] {
        states_.assign(rays.size(), PagedRayState{});
        run_queries<false>(rays, states_);
        for (size_t i = 0; i < rays.size(); ++i) {
            const bool found = states_[i].hit.found();
            hits[i] = found ? states_[i].hit : Hit{};
            if (!instances.empty()) instances[i] = found ? states_[i].instance : kNoInstance;
        }
    });
}

void PagedEngine::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) {
    std::lock_guard<std::mutex> lock(mutex_);
    parallel::with_threads(threads_, [&] {
        states_.assign(rays.size(), PagedRayState{});
        run_queries<true>(rays, states_);
        for (size_t i = 0; i < rays.size(); ++i) occluded[i] = states_[i].occluded ? 1 : 0;
    });
}

namespace {

// An object-space record in world space through its instance, as the
// in-core records of a world-space triangle would be: the wound normal
// through the normal matrix, flipped by a mirroring transform (the winding
// turns), shading normals through the normal matrix, the tangent through
// the linear part, the uv density over the area's scale.
ShadingTriangle to_world(const ShadingTriangle& t, const InstanceInfo& instance) {
    const float* w = instance.world_from_object;
    const float* o = instance.object_from_world;
    const auto linear = [&](Vec3f v) {
        return Vec3f(w[0] * v.x + w[1] * v.y + w[2] * v.z, w[4] * v.x + w[5] * v.y + w[6] * v.z,
                     w[8] * v.x + w[9] * v.y + w[10] * v.z);
    };
    const auto normal = [&](Vec3f n) {  // (object_from_world's linear part) transposed
        return Vec3f(o[0] * n.x + o[4] * n.y + o[8] * n.z, o[1] * n.x + o[5] * n.y + o[9] * n.z,
                     o[2] * n.x + o[6] * n.y + o[10] * n.z);
    };
    const float det = w[0] * (w[5] * w[10] - w[6] * w[9]) - w[1] * (w[4] * w[10] - w[6] * w[8]) +
                      w[2] * (w[4] * w[9] - w[5] * w[8]);
    ShadingTriangle r = t;
    const Vec3f g = normal(t.geometric_normal);
    const float g_length = length(g);
    r.geometric_normal = g_length > 0.0f ? g * ((det < 0.0f ? -1.0f : 1.0f) / g_length) : t.geometric_normal;
    if (t.flags & kHasNormals)
        for (uint32_t& n : r.normals) n = encode_octahedral(normalize(normal(decode_octahedral(n))));
    if (t.flags & kHasTangent) r.tangent = encode_octahedral(normalize(linear(decode_octahedral(t.tangent))));
    if (det < 0.0f) r.flags ^= kNegativeBitangent;
    const float area_scale = std::fabs(det) * g_length;
    if (area_scale > 0.0f) r.uv_area_ratio = t.uv_area_ratio / area_scale;
    return r;
}

}  // namespace

void PagedEngine::fetch_shading(std::span<const Hit> hits, std::span<ShadingTriangle> records,
                                std::span<const uint32_t> instances) {
    std::lock_guard<std::mutex> lock(mutex_);
    const ResidentHeader& r = file_->resident();
    const AttributeFormat format = r.attribute_format;
    const uint32_t record_bytes = attribute_record_bytes(format);
    const std::span<const PageInfo> pages = file_->pages();
    // Attribute page of hit i, and its triangle there.
    const auto locate = [&](const Hit& hit, uint32_t& page, uint32_t& triangle) {
        const uint32_t record = record_of(hit.prim);
        const PageInfo& info = pages[page_of(hit.prim)];
        page = info.first_attribute_page + record / info.attribute_triangles;
        triangle = record % info.attribute_triangles;
    };
    parallel::with_threads(threads_, [&] {
        pending_.clear();
        for (uint32_t i = 0; i < hits.size(); ++i) {
            if (hits[i].found()) pending_.push_back(i);
            else records[i] = ShadingTriangle{};
        }
        stats_.shading_fetches += pending_.size();
        std::vector<uint8_t> again(pending_.size());
        PageTableView table = attributes_->view();
        while (!pending_.empty()) {
            parallel::for_range(size_t(0), pending_.size(), size_t(kRayGrain), [&](size_t lo, size_t hi) {
                for (size_t k = lo; k < hi; ++k) {
                    const uint32_t i = pending_[k];
                    uint32_t page, triangle;
                    locate(hits[i], page, triangle);
                    table.request(page);
                    const uint8_t* bytes = table.cached(page);
                    again[k] = bytes == nullptr;
                    if (!bytes) continue;
                    records[i] = format == AttributeFormat::Shared
                                     ? decode_shared_record(bytes, triangle)
                                     : decode_attribute_record(bytes + size_t(triangle) * record_bytes, format);
                    if (!instances.empty() && instances[i] != kNoInstance)
                        records[i] = to_world(records[i], file_->instances()[instances[i]]);
                }
            });
            uint32_t kept = 0;
            for (size_t k = 0; k < pending_.size(); ++k)
                if (again[k]) pending_[kept++] = pending_[k];
            pending_.resize(kept);
            if (attributes_->swap_requested_pages() == 0 && !pending_.empty())
                throw Error(file_->path() + ": attribute loop made no progress (page manager loaded nothing)");
        }
    });
}

}  // namespace rf::pack
