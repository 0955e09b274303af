// rf::World: the scene a program renders and queries, with the structure
// that answers for it, on one device. A world owns its frame: the scene (a
// file, a built-in scene, a Scene handed over, or a paged .rfpack file), its
// world-space triangles, the acceleration structure kept current as time
// moves (Scene::set_time, the flat triangles updated, the structure refitted,
// adapted or rebuilt as WorldOptions::update says), and the device all of it
// lives on. Renderers made for a world read its structure at the start of
// each pass, so nothing is re-bound by hand after an update, on any device.
//
// The structure is built at the first commit: commit(), accel(), a query or
// the first make_renderer, whichever comes first; set_time before it only
// evaluates the scene, so a world opened and moved to its first frame is
// built once.
//
// Threading: a world may be used from several threads. Render passes and
// batched queries hold it shared; set_time, geometry_replaced,
// materials_changed and commit hold it exclusively, so they wait for passes
// and queries in flight to finish (a pass that starts after them sees the new
// frame), and passes that would start meanwhile wait for them. Calling one of
// them from inside a pass of the same world (its progress callback, on
// whichever of the pass's threads it runs) is an rf::Error, not a deadlock;
// a query from there is answered under the pass's hold. Between passes (a
// PassCallback of render_progressive) the world is free. Scene objects
// reached through scene() may
// only be changed while no pass runs (between passes of the only render
// thread, or with the renderers idle).
//
// Ownership: renderers share the world's state, so a world destroyed while
// renderers still exist leaves them rendering its last frame.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/progress.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/math/box.h"
#include "rayforge/math/ray.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/render/render.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Everything a world is made with. The device is named here once: the world
// builds its structure there (BuildOptions::device must be left at its
// default) and its renderers render there.
struct WorldOptions {
    Device device;
    BuildOptions build;        // the structure; on a CUDA device gpu_kernel picks the traversal
    UpdateOptions update;      // animated scenes: how the structure follows the motion
    PagedSceneOptions paged;   // .rfpack files: the page caches' budgets
};

// An animated world's time line (a still world: start == end == 0).
struct TimeRange {
    float start = 0.0f, end = 0.0f;
    float frames_per_second = 30.0f;
    [[nodiscard]] float frame_time(int frame) const { return start + float(frame) / frames_per_second; }
    [[nodiscard]] int frame_count() const;  // frames from start to end inclusive
};

// What the last commit made (a build, or the update of a set_time or
// geometry_replaced), and what the world holds.
enum class CommitKind : uint8_t { None, Build, Update };
struct WorldStats {
    uint64_t triangles = 0;
    size_t host_bytes = 0;       // scene, flat triangles and structure in host memory; a paged world: its
                                 // always-resident levels and page caches
    size_t device_bytes = 0;     // on a CUDA device: what the structure holds there
    double load_ms = 0.0;        // file to scene (a paged world: opening the file)
    CommitKind last_commit = CommitKind::None;
    double commit_ms = 0.0;      // the last commit's build or update
    uint64_t commits = 0;        // builds and updates so far
    AccelStats accel;            // the structure answering now (empty before the first commit)
    std::string update_method;   // the method that follows time and edits ("" for a still world whose edits rebuild)
};

class World;

// Opens what the CLI opens: a scene file (.obj + .mtl, .ply, .gltf, .glb,
// .aff, .json), builtin:NAME, or a paged scene file (.rfpack, opened with
// options.paged). Throws rf::Error for an unreadable file, invalid options,
// an unusable device or a request the device cannot serve (see
// check_world_options), before anything is built.
std::unique_ptr<World> open_world(const std::string& path_or_builtin, const WorldOptions& options = {},
                                  const LoadOptions& load = {});
// A world over `scene` (finalize()d by the loaders; make_world finalizes
// it otherwise).
std::unique_ptr<World> make_world(Scene scene, const WorldOptions& options = {});

// The checks open_world makes before loading: option ranges, the device, and
// explicit requests the device cannot serve (e.g. update method adapt on a
// CUDA device); with `path_or_builtin`, also what the device cannot do with
// that kind of scene (a paged file on a device that cannot render one).
// Throws rf::Error naming the option.
void check_world_options(const WorldOptions& options, const std::string& path_or_builtin = "");
// Whether a paged world (an .rfpack file) can live on `device`: the CPU only
// in this version (the rule check_world_options applies to paged files).
bool renders_paged_scenes(const Device& device);

struct WorldCore;    // the state a World shares with its renderers (library internal)
struct WorldAccess;  // (library internal)

class World {
public:
    ~World();
    World(const World&) = delete;
    World& operator=(const World&) = delete;

    [[nodiscard]] Device device() const;
    [[nodiscard]] bool paged() const;
    [[nodiscard]] bool animated() const;
    [[nodiscard]] TimeRange time_range() const;
    [[nodiscard]] float time() const;             // the time the world was last set to
    [[nodiscard]] Box3f bounds() const;
    [[nodiscard]] Camera camera() const;          // the scene's own camera at the current time (or one framing it)
    [[nodiscard]] WorldStats stats() const;
    // What the world substituted for a default the device cannot serve (a
    // scene file's update method, ...), one line each; empty when nothing was.
    [[nodiscard]] std::vector<std::string> notes() const;

    // The scene: an in-core world's meshes, instances, materials, lights and
    // environment; a paged world's lights, environment and camera (its
    // geometry stays in the file). Change materials, lights, textures or
    // the environment in place, then call materials_changed(); change mesh
    // positions or instance transforms, then call geometry_replaced().
    [[nodiscard]] Scene& scene();
    [[nodiscard]] const Scene& scene() const;
    // The flat world-space triangles (empty for a paged world).
    [[nodiscard]] const SceneGeometry& geometry() const;
    // A paged world's page caches and query statistics; rf::Error otherwise.
    [[nodiscard]] PagedScene& paged_scene() const;

    // Builds the structure if it is not built yet (progress: the build's
    // fraction, on this thread); returns the stats of the last commit.
    WorldStats commit(const ProgressCallback& progress = {});
    // The structure answering now, on device(); committed first. The reference
    // is valid until the next set_time, geometry_replaced or materials_changed.
    [[nodiscard]] const Accel& accel() const;

    // Moves an animated world to time t (seconds): the scene evaluated, its
    // triangles and structure updated by the update method. A still world
    // only records t. Returns the update's work (empty before the first
    // commit and when nothing moved).
    UpdateStats set_time(float t);
    // The materials, lights, textures, environment or meshes' material ids
    // changed in place: indices are checked (rf::Error), the triangles'
    // materials and the emitters found again, and renderers rebuild their
    // shading tables at their next pass.
    void materials_changed();
    // Meshes' positions (or instance transforms and visibility) changed in
    // place, as `change` names them (instances of a named mesh are added):
    // the triangles and the structure follow, by the update method of an
    // animated world or of a still world made with WorldOptions::update.method
    // set (e.g. refit for moving vertices), by a rebuild otherwise. A mesh
    // whose triangle count changed makes the world flatten and build again.
    UpdateStats geometry_replaced(const GeometryChange& change);

    // A new world over this one's scene as it is now (a copy, at the current
    // time, with its edits; a paged world's file opened again) made with
    // other options: another structure, update method or device. This
    // world is held shared while its scene is copied; the new one is not
    // committed yet.
    [[nodiscard]] std::unique_ptr<World> reopen(const WorldOptions& options) const;

    // Ray queries through accel(), holding the world shared.
    [[nodiscard]] Hit intersect(const Ray& ray) const;
    [[nodiscard]] bool occluded(const Ray& ray) const;
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    // Rays and answers in the world's CUDA device memory (Accel::intersect_on_device).
    void intersect_on_device(const Ray* rays, Hit* hits, size_t count, void* stream = nullptr) const;
    void occluded_on_device(const Ray* rays, uint8_t* occluded, size_t count, void* stream = nullptr) const;

private:
    friend struct WorldAccess;  // the library's own door to the core
    explicit World(std::shared_ptr<WorldCore> core);
    std::shared_ptr<WorldCore> core_;
};

// A progressive renderer for `world`, on world.device(), reading the world's
// structure and scene at the start of every pass (so set_time,
// materials_changed and geometry_replaced restart its accumulation). The
// world is committed first. Throws rf::Error for invalid options.
std::unique_ptr<Renderer> make_renderer(World& world, const Camera& camera, const RenderOptions& options);

// make_renderer, render_progressive, and the mean image.
Image render(World& world, const Camera& camera, const RenderOptions& options, const ProgressCallback& progress = {});

}  // namespace rf
