// rf::World (rayforge/world.h) and the core it shares with its renderers
// (world/world_core.h): opening, the lazy first build, the frame protocol
// (set_time: the scene evaluated, its triangles and structure updated, the
// version bumped so that renderers follow at their next pass), edits, and
// queries under the frame lock.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <utility>

#include "core/assert.h"
#include "rayforge/core/error.h"
#include "scene/animation_eval.h"
#include "world/world_core.h"

namespace rf {

struct WorldAccess {
    static std::unique_ptr<World> make(std::shared_ptr<WorldCore> core) {
        return std::unique_ptr<World>(new World(std::move(core)));
    }
    static const std::shared_ptr<WorldCore>& core(const World& world) { return world.core_; }
};

std::shared_ptr<WorldCore> core_of(World& world) { return WorldAccess::core(world); }

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The worlds this thread holds shared (a pass, a query batch): a nested
// reading of one of them must not lock again (a waiting writer would then
// wait for it while it waits for the writer), and a write would wait for
// itself.
thread_local std::vector<const WorldCore*> t_reading;

bool reading_on_this_thread(const WorldCore* core) {
    return std::find(t_reading.begin(), t_reading.end(), core) != t_reading.end();
}

// A paged file's scene as renderers see it: its lights, environment and
// camera, one default material (the renderer reads the file's), and bounds.
void fill_paged_shell(const PagedScene& paged, Scene& scene, SceneGeometry& geometry) {
    scene.source = paged.info().path;
    scene.lights = paged.lights();
    scene.environment = paged.environment();
    scene.materials.push_back(Material{});
    scene.camera = paged.camera();
    geometry.bounds = paged.info().bounds;
}

// Instances whose transform is not finite would put NaNs into the triangles.
void check_change(const Scene& scene, const GeometryChange& change) {
    for (uint32_t m : change.meshes) {
        if (m >= scene.meshes.size())
            throw Error("geometry_replaced: mesh " + std::to_string(m) + " of " + std::to_string(scene.meshes.size()));
        scene.meshes[m].validate();
    }
    for (uint32_t i : change.instances) {
        if (i >= scene.instances.size())
            throw Error("geometry_replaced: instance " + std::to_string(i) + " of " +
                        std::to_string(scene.instances.size()));
        if (scene.instances[i].mesh >= scene.meshes.size())
            throw Error("geometry_replaced: instance " + std::to_string(i) + " references mesh " +
                        std::to_string(scene.instances[i].mesh) + " of " + std::to_string(scene.meshes.size()));
        const Affine3f& m = scene.instances[i].transform;
        if (!std::all_of(&m.m[0][0], &m.m[0][0] + 12, [](float v) { return std::isfinite(v); }))
            throw Error("geometry_replaced: instance " + std::to_string(i) + " has a non-finite transform");
    }
}

// The change as SceneGeometry::update takes it: sorted, with the instances of every named mesh.
GeometryChange completed(const Scene& scene, GeometryChange change) {
    std::vector<char> moved(scene.meshes.size(), 0);
    for (uint32_t m : change.meshes) moved[m] = 1;
    for (uint32_t i = 0; i < scene.instances.size(); ++i)
        if (moved[scene.instances[i].mesh]) change.instances.push_back(i);
    for (std::vector<uint32_t>* ids : {&change.meshes, &change.instances}) {
        std::sort(ids->begin(), ids->end());
        ids->erase(std::unique(ids->begin(), ids->end()), ids->end());
    }
    return change;
}

// Whether the flat triangles can be rewritten in place: the same instances
// with the same triangle counts.
bool same_layout(const Scene& scene, const SceneGeometry& geometry, const GeometryChange& change) {
    if (geometry.instance_first_triangle.size() != scene.instances.size() + 1) return false;
    for (uint32_t i : change.instances) {
        const size_t count = geometry.instance_first_triangle[i + 1] - geometry.instance_first_triangle[i];
        if (count != scene.meshes[scene.instances[i].mesh].triangle_count()) return false;
    }
    return true;
}

}  // namespace

// ---- the core

WorldCore::WorldCore(Scene loaded, const WorldOptions& options, double loading_ms)
    : device(options.device),
      kind(loaded.animated() ? WorldKind::Animated : WorldKind::Still),
      scene(std::move(loaded)) {
    const Clock::time_point start = Clock::now();
    plan = plan_world(options, kind, scene.render_settings.update);  // the device was checked before loading
    scene.finalize();  // the loaders' scenes are final already; a program's may not be
    if (kind == WorldKind::Animated && !scene.animation.evaluated) scene.set_time(scene.animation.start);
    time = scene.time;
    geometry = SceneGeometry::build(scene);
    load_ms = loading_ms + ms_since(start);
}

WorldCore::WorldCore(std::unique_ptr<PagedScene> opened, const WorldOptions& options, double loading_ms)
    : device(options.device), kind(WorldKind::Paged), paged(std::move(opened)) {
    plan = plan_world(options, kind, std::nullopt);
    fill_paged_shell(*paged, scene, geometry);
    load_ms = loading_ms;
    built.store(true, std::memory_order_release);  // its structure came with the file
}

WorldCore::FrameReading::FrameReading(const WorldCore& core, Commit commit) : core_(core) {
    if (commit == Commit::Yes && !core.committed()) const_cast<WorldCore&>(core).commit({});
    if (reading_on_this_thread(&core)) return;
    core.lock.lock_shared();
    t_reading.push_back(&core);
    locked_ = true;
}

WorldCore::FrameReading::~FrameReading() {
    if (!locked_) return;
    t_reading.erase(std::find(t_reading.begin(), t_reading.end(), &core_));
    core_.lock.unlock_shared();
}

WorldCore::OnBehalfOfReading::OnBehalfOfReading(const WorldCore& core) : core_(core) { t_reading.push_back(&core); }

WorldCore::OnBehalfOfReading::~OnBehalfOfReading() {
    t_reading.erase(std::find(t_reading.begin(), t_reading.end(), &core_));
}

WorldCore::FrameWriting::FrameWriting(WorldCore& core, const char* what) : core_(core) {
    if (reading_on_this_thread(&core))
        throw Error(std::string(what) + ": called from inside a render pass or query of the same world, which "
                                        "holds it; call it between passes");
    core.lock.lock();
}

WorldCore::FrameWriting::~FrameWriting() { core_.lock.unlock(); }

const Accel& WorldCore::current_accel() const {
    if (paged) return paged->accel();
    if (dynamic_accel) return dynamic_accel->current();
    RF_ASSERT(still_accel, "a committed world without a structure");
    return *still_accel;
}

void WorldCore::commit(const ProgressCallback& progress) {
    if (committed()) return;
    const FrameWriting writing(*this, "commit");
    if (committed()) return;  // another thread built it while this one waited
    build(progress);
}

void WorldCore::build(const ProgressCallback& progress) {
    const Clock::time_point start = Clock::now();
    still_accel.reset();  // the old structure's memory goes before the new one is built
    dynamic_accel.reset();
    built.store(false, std::memory_order_release);
    if (plan.dynamic_bvh) {
        dynamic_accel = build_dynamic_accel(scene, geometry, plan.build, plan.update, progress);
    } else {
        still_accel = build_accel(geometry, plan.build, progress);
    }
    commit_ms = ms_since(start);
    last_commit = CommitKind::Build;
    ++commits;
    ++version;
    built.store(true, std::memory_order_release);
}

// The structure follows moved triangles: the dynamic accel's update method,
// or a rebuild of a still structure. A failed update leaves the world
// uncommitted, so the next use builds it again from the triangles.
UpdateStats WorldCore::update_structure(const GeometryChange& change) {
    UpdateStats stats;
    try {
        if (dynamic_accel) {
            stats = dynamic_accel->update(change);
        } else {
            const Clock::time_point start = Clock::now();
            still_accel.reset();
            still_accel = build_accel(geometry, plan.build);
            const AccelStats built_stats = still_accel->stats();
            stats.update_ms = ms_since(start);
            stats.layout_ms = built_stats.layout_ms;
            stats.sah_cost = built_stats.sah_cost;
        }
    } catch (...) {
        still_accel.reset();
        dynamic_accel.reset();
        built.store(false, std::memory_order_release);
        throw;
    }
    stats.updated = true;
    last_commit = CommitKind::Update;
    commit_ms = stats.update_ms;
    ++commits;
    return stats;
}

UpdateStats WorldCore::set_time(float t) {
    if (!std::isfinite(t)) throw Error("set_time: the time must be finite");
    const FrameWriting writing(*this, "set_time");
    time = t;
    if (kind != WorldKind::Animated) return {};
    const GeometryChange change = scene.set_time(t);
    if (!change.geometry()) return {};
    geometry.update(scene, change);
    ++version;
    if (!committed()) return {};
    return update_structure(change);
}

UpdateStats WorldCore::geometry_replaced(GeometryChange change) {
    if (kind == WorldKind::Paged) throw Error("geometry_replaced: a paged world's geometry stays in its file");
    const FrameWriting writing(*this, "geometry_replaced");
    check_change(scene, change);
    change = completed(scene, std::move(change));
    if (!change.geometry()) return {};
    ++version;
    if (!same_layout(scene, geometry, change)) {  // triangles added or removed: flatten and build again
        scene.finalize();
        geometry = SceneGeometry::build(scene);
        if (!committed()) return {};
        build({});
        UpdateStats stats;
        stats.updated = true;
        stats.update_ms = commit_ms;
        return stats;
    }
    geometry.update(scene, change);
    if (!committed()) return {};
    return update_structure(change);
}

void WorldCore::materials_changed() {
    const FrameWriting writing(*this, "materials_changed");
    if (kind != WorldKind::Paged) {
        scene.validate_materials();
        geometry.update_materials(scene);  // mesh material ids may have changed too
    }
    ++version;
}

WorldStats WorldCore::stats() const {
    WorldStats s;
    const FrameReading frame(*this, FrameReading::Commit::No);
    s.load_ms = load_ms;
    s.last_commit = last_commit;
    s.commit_ms = commit_ms;
    s.commits = commits;
    if (kind == WorldKind::Animated || plan.dynamic_bvh) s.update_method = to_string(*plan.update.method);
    if (paged) {
        s.triangles = paged->info().triangles;
        s.host_bytes = paged->memory_bytes();
    } else {
        s.triangles = geometry.size();
        s.host_bytes = scene.memory_bytes() + geometry.memory_bytes();
    }
    if (committed()) {
        s.accel = current_accel().stats();
        if (!paged) s.host_bytes += s.accel.bytes;
        s.device_bytes = s.accel.device_bytes;
    }
    return s;
}

// ---- World

int TimeRange::frame_count() const { return animation_frame_count(start, end, frames_per_second); }

World::World(std::shared_ptr<WorldCore> core) : core_(std::move(core)) {}
World::~World() = default;

Device World::device() const { return core_->device; }
bool World::paged() const { return core_->kind == WorldKind::Paged; }
bool World::animated() const { return core_->kind == WorldKind::Animated; }
float World::time() const {
    const WorldCore::FrameReading frame(*core_, WorldCore::FrameReading::Commit::No);
    return core_->time;
}
WorldStats World::stats() const { return core_->stats(); }
std::vector<std::string> World::notes() const { return core_->plan.notes; }
Scene& World::scene() { return core_->scene; }
const Scene& World::scene() const { return core_->scene; }
const SceneGeometry& World::geometry() const { return core_->geometry; }

TimeRange World::time_range() const {
    const Animation& a = core_->scene.animation;  // set when loaded; set_time changes no range
    return {a.start, a.end, a.frames_per_second};
}

Box3f World::bounds() const {
    const WorldCore::FrameReading frame(*core_, WorldCore::FrameReading::Commit::No);
    return core_->geometry.bounds;
}

Camera World::camera() const {
    const WorldCore::FrameReading frame(*core_, WorldCore::FrameReading::Commit::No);
    return core_->scene.camera_or_default();
}

PagedScene& World::paged_scene() const {
    if (!core_->paged) throw Error("paged_scene: " + core_->scene.source + " is not a paged scene");
    return *core_->paged;
}

WorldStats World::commit(const ProgressCallback& progress) {
    core_->commit(progress);
    return core_->stats();
}

const Accel& World::accel() const {
    core_->commit({});
    return core_->current_accel();
}

std::unique_ptr<World> World::reopen(const WorldOptions& options) const {
    if (core_->paged) return open_world(core_->paged->info().path, options);
    check_world_options(options);
    Scene copy;
    {
        const WorldCore::FrameReading frame(*core_, WorldCore::FrameReading::Commit::No);
        copy = core_->scene;
    }
    return make_world(std::move(copy), options);
}

UpdateStats World::set_time(float t) { return core_->set_time(t); }
void World::materials_changed() { core_->materials_changed(); }
UpdateStats World::geometry_replaced(const GeometryChange& change) { return core_->geometry_replaced(change); }

Hit World::intersect(const Ray& ray) const {
    const WorldCore::FrameReading frame(*core_);
    return frame.accel().intersect(ray);
}

bool World::occluded(const Ray& ray) const {
    const WorldCore::FrameReading frame(*core_);
    return frame.accel().occluded(ray);
}

void World::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
    const WorldCore::FrameReading frame(*core_);
    frame.accel().intersect(rays, hits);
}

void World::occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const {
    const WorldCore::FrameReading frame(*core_);
    frame.accel().occluded(rays, occluded);
}

void World::intersect_on_device(const Ray* rays, Hit* hits, size_t count, void* stream) const {
    const WorldCore::FrameReading frame(*core_);
    frame.accel().intersect_on_device(rays, hits, count, stream);
}

void World::occluded_on_device(const Ray* rays, uint8_t* occluded, size_t count, void* stream) const {
    const WorldCore::FrameReading frame(*core_);
    frame.accel().occluded_on_device(rays, occluded, count, stream);
}

// ---- making worlds

std::unique_ptr<World> open_world(const std::string& path, const WorldOptions& options, const LoadOptions& load) {
    const Clock::time_point start = Clock::now();
    check_world_options(options, path);  // before anything is read
    if (is_paged_scene_file(path)) {
        std::unique_ptr<PagedScene> paged = open_paged_scene(path, options.paged);
        return WorldAccess::make(std::make_shared<WorldCore>(std::move(paged), options, ms_since(start)));
    }
    Scene scene = load_scene(path, load);
    return WorldAccess::make(std::make_shared<WorldCore>(std::move(scene), options, ms_since(start)));
}

std::unique_ptr<World> make_world(Scene scene, const WorldOptions& options) {
    check_world_options(options);
    return WorldAccess::make(std::make_shared<WorldCore>(std::move(scene), options, 0.0));
}

}  // namespace rf
