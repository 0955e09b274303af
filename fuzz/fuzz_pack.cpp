// Paged scene files (.rfpack, src/ooc/pack_format.h): opened, every page
// read, traced, shaded, textured and rendered, under a tiny memory budget.
//
// Input: one mode byte, then the file's bytes. The file carries CRC-32C
// checksums (header, directory, resident section, every page), so a random
// mutation is nearly always turned away at open or at its page's read. Mode
// bit 0 therefore recomputes them (and, with bit 1, the header's file size)
// before the file is written, so the mutated contents reach the structure
// checks and the traversal with well-formed checksums: node indices and
// counts, offsets and sizes, bounds and decode transforms (NaN, inf,
// degenerate), texture sizes, material texture ids. Bit 2 gives the page
// managers two slots instead of one, bits 3-4 pick the integrator of the
// final render (path, Whitted, AO, normals), bit 5 its camera (the file's,
// else one framing the scene's bounds).
//
// What must succeed or throw rf::Error, in this order (a failure of one step
// does not skip the next):
//   1. rf::pack::PackFile opens the file; every directory entry is read
//      (PackFile::read_page), every geometry page viewed and walked
//      (view_geometry_page);
//   2. rf::decode_paged_geometry (every page, in core);
//   3. rf::open_world with budgets of one or two slots per manager;
//      a batch of fixed rays (and rays aimed at the scene's bounds) through
//      accel().intersect / occluded, batched and single; the shading records
//      of the hits (PagedEngine::fetch_shading); again from cold caches;
//   4. every texture sampled at a few uvs on every level and at a few
//      levels of detail;
//   5. a 4x4 render of one pass (rf::make_renderer of the world);
//   6. rays from very far away, with NaN and infinite components, with a
//      denormal direction, one batch each (last, so that a reproducer of an
//      earlier step does not stop here first).
// FUZZ_PACK_TRACE=1 in the environment prints each step's outcome (and the
// rf::Error it threw) to stderr, for reading a reproducer.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "ooc/pack_file.h"
#include "ooc/pack_format.h"
#include "ooc/paged_engine.h"
#include "ooc/paged_scene_impl.h"
#include "ooc/paged_texture.h"
#include "ooc/texture_cache.h"
#include "rayforge/core/error.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/world.h"
#include "rayforge/render/render.h"

namespace {

using namespace rf;
using namespace rf::pack;

constexpr uint8_t kFixChecksums = 1;
constexpr uint8_t kFixFileSize = 2;
constexpr uint8_t kTwoSlots = 4;
constexpr uint8_t kFileCamera = 32;

const bool g_trace = std::getenv("FUZZ_PACK_TRACE") != nullptr;

// One step of the contract: success or rf::Error (anything else escapes to libFuzzer).
template <class F>
void step(const char* name, F&& run) {
    try {
        run();
        if (g_trace) std::fprintf(stderr, "fuzz_pack: %s: ok\n", name);
    } catch (const rf::Error& e) {
        if (g_trace) std::fprintf(stderr, "fuzz_pack: %s: rf::Error: %s\n", name, e.what());
    }
}

// No budget derived from the file goes past this (the fuzz budget is 256 MB).
constexpr size_t kMaxManagerBudget = size_t(64) << 20;

template <class T>
bool load(const std::vector<uint8_t>& bytes, uint64_t offset, T& out) {
    if (offset > bytes.size() || sizeof(T) > bytes.size() - offset) return false;
    std::memcpy(&out, bytes.data() + offset, sizeof(T));
    return true;
}

template <class T>
void store(std::vector<uint8_t>& bytes, uint64_t offset, const T& value) {
    std::memcpy(bytes.data() + offset, &value, sizeof(T));
}

bool in_file(const std::vector<uint8_t>& bytes, uint64_t offset, uint64_t count) {
    return offset <= bytes.size() && count <= bytes.size() - offset;
}

// Makes every checksum the file names right for its bytes as they are now:
// each page's (in its directory entry), the directory's, the resident
// section's and the header's; with kFixFileSize also the header's file size.
// Ranges outside the file are left as they are (the reader must refuse them).
void fix_checksums(std::vector<uint8_t>& bytes, uint8_t mode) {
    FileHeader h;
    if (!load(bytes, 0, h)) return;
    if (mode & kFixFileSize) h.file_bytes = bytes.size();
    if (h.page_count <= bytes.size() / sizeof(PageEntry) &&
        in_file(bytes, h.directory_offset, h.page_count * sizeof(PageEntry))) {
        for (uint64_t i = 0; i < h.page_count; ++i) {
            const uint64_t at = h.directory_offset + i * sizeof(PageEntry);
            PageEntry e;
            load(bytes, at, e);
            if (!in_file(bytes, e.offset, e.stored_bytes)) continue;
            e.checksum = crc32c(bytes.data() + e.offset, e.stored_bytes);
            store(bytes, at, e);
        }
        h.directory_checksum = crc32c(bytes.data() + h.directory_offset, size_t(h.page_count) * sizeof(PageEntry));
    }
    if (in_file(bytes, h.resident_offset, h.resident_bytes))
        h.resident_checksum = crc32c(bytes.data() + h.resident_offset, size_t(h.resident_bytes));
    h.header_checksum = crc32c(&h, offsetof(FileHeader, header_checksum));
    store(bytes, 0, h);
}

// Keeps the optimiser from dropping the reads of a page's parts.
volatile uint32_t g_sink = 0;

// Step 1: every page read; geometry pages viewed and every node and quad touched.
void read_every_page(const PackFile& file) {
    std::vector<uint8_t> bytes, scratch;
    for (uint64_t i = 0; i < file.directory().size(); ++i) {
        step("read_page", [&] {
            file.read_page(i, bytes, scratch);
            if (i >= file.header().geometry_pages) return;
            const GeometryPageView v = view_geometry_page(bytes, "page " + std::to_string(i));
            uint32_t sum = 0;
            for (uint32_t n = 0; n < v.node_count; ++n) sum += v.nodes[n].base_index_child + v.nodes[n].q_hi_z[7];
            for (uint32_t q = 0; q < v.quad_count; ++q) sum += uint16_t(v.quads[q].v[3][2]);
            g_sink = g_sink + sum;
        });
    }
}

// Fixed rays, plus rays from outside the scene's bounds through its centre
// and corners and from its centre outwards; some with tmin/tmax cut short,
// axis-parallel (zero direction components) and tiny directions.
std::vector<Ray> test_rays(const Box3f& bounds) {
    std::vector<Ray> rays;
    const auto add = [&](Vec3f org, Vec3f dir, float tmin = 0.0f, float tmax = kInfinity) {
        Ray r;
        r.org = org;
        r.dir = dir;
        r.tmin = tmin;
        r.tmax = tmax;
        rays.push_back(r);
    };
    add({0, 0, 5}, {0, 0, -1});
    add({0.3f, 0.2f, 5}, {0, 0, -1}, 0.0f, 4.0f);
    add({-5, 0.1f, 0.1f}, {1, 0, 0});
    add({0.1f, 5, -0.1f}, {0, -1, 0});
    add({-3, -3, -3}, {1, 1, 1});
    add({0, 0, 0}, {0.3f, -0.5f, 0.8f});
    add({1e4f, 1e4f, 1e4f}, {-1, -1, -1}, 1.0f, 1e30f);
    add({0, 0, 5}, {1e-20f, 1e-20f, -1e-20f});
    const bool finite = std::isfinite(bounds.lo.x) && std::isfinite(bounds.lo.y) && std::isfinite(bounds.lo.z) &&
                        std::isfinite(bounds.hi.x) && std::isfinite(bounds.hi.y) && std::isfinite(bounds.hi.z);
    if (!finite) return rays;
    const Vec3f centre = (bounds.lo + bounds.hi) * 0.5f;
    const Vec3f extent = bounds.hi - bounds.lo;
    const float reach = std::max({extent.x, extent.y, extent.z, 1e-3f}) * 2.0f;
    const Vec3f dirs[] = {{0, 0, -1}, {0, 0, 1}, {1, 0, 0}, {0, -1, 0}, {0.577f, 0.577f, 0.577f},
                          {-0.3f, 0.8f, -0.52f}, {0.6f, 0, -0.8f}};
    for (const Vec3f& d : dirs) add(centre - d * reach, d);
    for (const Vec3f& d : dirs) add(centre, d, 1e-4f);
    for (int c = 0; c < 8; ++c) {
        const Vec3f corner((c & 1) ? bounds.hi.x : bounds.lo.x, (c & 2) ? bounds.hi.y : bounds.lo.y,
                           (c & 4) ? bounds.hi.z : bounds.lo.z);
        add(corner + (corner - centre) * 0.5f, centre - corner);
    }
    add(centre - Vec3f(reach, 0, 0), {1, 0, 0}, 0.0f, reach);  // ends at the centre
    add(bounds.lo - Vec3f(1, 0, 0), {1, 0, 0});                // along an edge of the bounds
    return rays;
}

// Rays from very far away, with NaN and infinite components (as a camera read
// from the file can make them), and with a denormal direction and an infinite
// tmax; traced one batch each, in this order.
std::vector<Ray> extreme_rays(const Box3f& bounds) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    std::vector<Ray> rays = {
        {{-1e30f, 0.5f, 0.25f}, 0.0f, {1, 0, 0}, kInfinity},
        {{3e37f, -2e37f, 1e37f}, 0.0f, {-0.8f, 0.53f, -0.27f}, kInfinity},
        {{nan, 0, 5}, 0.0f, {0, 0, -1}, kInfinity},
        {{0, 0, 5}, 0.0f, {0.1f, nan, -1}, kInfinity},
        {{inf, 0.2f, 0.1f}, 0.0f, {-1, 0, 0}, kInfinity},
        {{0, 0, 5}, nan, {0, 0, -1}, nan},
        {{nan, nan, nan}, 0.0f, {nan, nan, nan}, kInfinity},
        {{0, 0, 5}, 0.0f, {0, 0, -1}, inf},
        {{0.5f, 0.5f, 0.25f}, 0.0f, {1e-39f, 0, 0}, inf},
    };
    const Vec3f centre = (bounds.lo + bounds.hi) * 0.5f;
    if (std::isfinite(centre.x) && std::isfinite(centre.y) && std::isfinite(centre.z))
        rays.push_back({centre, 0.0f, {0, 0, 1e-39f}, inf});
    return rays;
}

// The budget that gives a manager of `pages` pages of `slot_bytes` exactly `slots` slots.
size_t cache_budget(uint64_t pages, size_t slot_bytes, uint32_t slots) {
    const uint64_t b =
        pages * PageCache::kTableBytesPerPage + uint64_t(slots) * (slot_bytes + PageCache::kBookkeepingBytesPerSlot);
    return size_t(std::min<uint64_t>(b, kMaxManagerBudget));
}

PagedSceneOptions scene_options(const PackFile* file, uint8_t mode) {
    PagedSceneOptions o;
    o.memory_budget = size_t(1) << 20;
    o.threads = 1;
    if (!file) return o;
    const uint32_t slots = (mode & kTwoSlots) ? 2 : 1;
    const FileHeader& h = file->header();
    uint32_t largest = 1;
    for (uint64_t i = 0; i < h.geometry_pages; ++i) largest = std::max(largest, file->directory()[i].raw_bytes);
    o.geometry_budget = cache_budget(h.geometry_pages, largest, slots);
    o.attribute_budget = cache_budget(h.attribute_pages, file->resident().attribute_page_bytes, slots);
    o.texture_budget = TextureTileCache::budget_for_slots(std::min(TextureTileCache::kMinSlots, h.texture_pages));
    return o;
}

// Steps 3 and 6: a batch of rays, closest and any hit, then the hits' shading records.
void trace(PagedScene& scene, PagedSceneImpl& impl, const std::vector<Ray>& rays) {
    std::vector<Hit> hits(rays.size());
    std::vector<uint8_t> occluded(rays.size());
    std::vector<ShadingTriangle> records(rays.size());
    for (int round = 0; round < 2; ++round) {
        scene.accel().intersect(rays, hits);
        scene.accel().occluded(rays, occluded);
        impl.engine().fetch_shading(hits, records);
        uint32_t found = 0, blocked = 0;
        for (size_t i = 0; i < hits.size(); ++i) {
            if (hits[i].found()) g_sink = g_sink + records[i].material + uint32_t(records[i].flags);
            found += hits[i].found() ? 1 : 0;
            blocked += occluded[i];
        }
        if (g_trace) std::fprintf(stderr, "fuzz_pack: %zu rays: %u hits, %u occluded\n", rays.size(), found, blocked);
        scene.clear_caches();  // the second round from cold caches
    }
    const Hit one = scene.accel().intersect(rays.front());
    const bool any = scene.accel().occluded(rays.back());
    g_sink = g_sink + one.prim + uint32_t(any);
    (void)scene.caches();
    (void)scene.query_stats();
    (void)scene.memory_bytes();
}

// Step 4: every texture on every level at a few uvs, and at a few levels of detail.
void sample_textures(const PagedSceneImpl& impl) {
    const Vec2f uvs[] = {{0.0f, 0.0f}, {0.5f, 0.5f}, {0.999f, 1.0f}, {-0.25f, 1.75f}, {3.1f, -7.9f}, {1000.3f, -1000.6f}};
    const float lods[] = {-1.0f, 0.0f, 0.5f, 2.7f, 40.0f, std::numeric_limits<float>::quiet_NaN()};
    float sum = 0.0f;
    for (const PagedTexture& t : impl.textures()) {
        for (uint32_t level = 0; level < t.info->level_count; ++level)
            for (const Vec2f& uv : uvs) sum += sample_texture(t, int(level), uv).x;
        for (const Vec2f& uv : uvs)
            for (float lod : lods) sum += sample_texture_at(t, uv, lod).w;
    }
    g_sink = g_sink + uint32_t(sum != sum);
    if (g_trace) std::fprintf(stderr, "fuzz_pack: %zu textures sampled\n", impl.textures().size());
}

// A camera looking at the middle of `bounds` from the +z side, close enough
// that a 4x4 image sees the scene (the file's camera may frame it loosely).
Camera camera_on(const Box3f& bounds) {
    Camera c;
    const Vec3f centre = (bounds.lo + bounds.hi) * 0.5f;
    const Vec3f extent = bounds.hi - bounds.lo;
    c.target = centre;
    c.eye = centre + Vec3f(0.05f * extent.x, 0.1f * extent.y, 0.5f * extent.z + 1.2f * std::max(extent.x, extent.y));
    return c;
}

// Step 5: a 4x4 render, one pass, with the file's camera or one on the scene's bounds.
void render(World& world, uint8_t mode) {
    const PagedScene& scene = world.paged_scene();
    RenderOptions options;
    options.width = 4;
    options.height = 4;
    options.spp = 1;
    options.threads = 1;
    options.max_depth = 3;
    options.ao_samples = 2;
    const IntegratorKind kinds[] = {IntegratorKind::Path, IntegratorKind::Whitted, IntegratorKind::AmbientOcclusion,
                                    IntegratorKind::Normals};
    options.integrator = kinds[(mode >> 3) & 3];
    const Camera camera = (mode & kFileCamera) ? scene.camera() : camera_on(scene.info().bounds);
    const std::unique_ptr<Renderer> renderer = make_renderer(world, camera, options);
    renderer->render_pass();
    g_sink = g_sink + uint32_t(renderer->image().pixels.size());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    if (size < 1) return 0;
    const uint8_t mode = data[0];
    std::vector<uint8_t> bytes(data + 1, data + size);
    if (mode & kFixChecksums) fix_checksums(bytes, mode);
    const std::string path = rf::fuzz::write_scratch("in.rfpack", bytes.data(), bytes.size());

    std::unique_ptr<PackFile> file;
    step("PackFile", [&] {
        file = std::make_unique<PackFile>(path);
        (void)file->camera();
        (void)file->environment();
        (void)file->resident_memory_bytes();
        read_every_page(*file);
    });
    if (!file) return 0;  // open_world opens the same way; nothing further can open
    step("decode_paged_geometry", [&] { (void)decode_paged_geometry(path); });

    std::unique_ptr<World> world;
    step("open_world", [&] {
        WorldOptions options;
        options.paged = scene_options(file.get(), mode);
        world = open_world(path, options);
    });
    if (!world) return 0;
    PagedScene* scene = &world->paged_scene();
    auto& impl = dynamic_cast<PagedSceneImpl&>(*scene);
    (void)scene->info();
    step("trace", [&] { trace(*scene, impl, test_rays(impl.file().resident().bounds)); });
    step("sample_textures", [&] { sample_textures(impl); });
    step("render", [&] { render(*world, mode); });
    for (const Ray& ray : extreme_rays(impl.file().resident().bounds))
        step("trace an extreme ray", [&] { trace(*scene, impl, {ray}); });
    return 0;
}
