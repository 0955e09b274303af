// The engine side of the viewer, on two threads of its own so the window
// never waits for it:
//  - the job thread opens scenes as rf::World objects and builds their
//    structures (one job at a time; a newer request replaces a queued one),
//    reporting progress; a structure setting changed reopens the shown
//    world with the new options (World::reopen: its scene at its current
//    time), and until the new world is built the old one keeps rendering;
//  - the render thread owns the shown world's rf::Renderer: it applies the
//    latest camera and settings, moves an animated world through time
//    (World::set_time; the renderer follows the world by itself), runs
//    passes (cancelling a full-resolution pass the moment anything
//    changes), renders reduced-resolution previews while the camera moves,
//    tone-maps each pass into a display image and publishes it as a Frame.
// The window's thread only posts requests and reads the latest Frame and
// Status; every call here returns at once.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "rayforge/render/display.h"
#include "rayforge/render/render.h"
#include "rayforge/world.h"
#include "view_settings.h"

namespace rf::viewer {

using Clock = std::chrono::steady_clock;

// Where a scene comes from: a file, builtin:NAME, or a views.json entry
// with its benchmark views and point light.
struct SceneSource {
    std::string name;            // shown in the window
    std::string path;            // what rf::load_scene opens
    std::vector<Camera> views;   // benchmark views (bookmarks); the first is the start camera
    std::optional<Vec3f> light;  // views.json point light, added when the scene has no light
};

// A loaded scene as the window sees it; never changed once published (the
// world itself lives in the session and moves through time).
struct SceneData {
    uint64_t id = 0;  // increases with every load
    SceneSource source;
    SceneKind kind = SceneKind::InCore;  // a paged scene file (.rfpack) brings its structure
    Camera camera;          // the start camera
    float size = 1.0f;      // the bounds' diagonal
    double load_ms = 0.0;   // file to flat triangles (a paged scene: opening it)
    size_t triangles = 0;
};

// One displayed image and what it shows.
struct Frame {
    std::shared_ptr<const DisplayImage> image;
    uint64_t sequence = 0;        // increases with every frame
    int passes = 0;               // accumulated in this image
    int target_passes = 0;        // where accumulation stops
    bool preview = false;         // reduced resolution while the camera moves
    double pass_ms = 0.0;         // the last pass
    uint64_t pass_rays = 0;       // rays of the last pass
    uint64_t camera_version = 0;  // of the camera it was rendered with
    Clock::time_point camera_time;  // when that camera was asked for
    uint64_t settings_version = 0;  // of the settings it was rendered with
    uint64_t target_version = 0;    // of the scene and structure it was rendered with
    uint64_t time_version = 0;      // of the animation time asked for (Session::set_time)
};

// The latest requests, to tell whether a Frame shows all of them.
struct Versions {
    uint64_t camera = 0, settings = 0, target = 0, time = 0;
    bool jobs_pending = false;  // a load or build is queued or running
    [[nodiscard]] bool shown_by(const Frame& frame) const {
        return !jobs_pending && frame.camera_version == camera && frame.settings_version == settings &&
               frame.target_version == target && frame.time_version == time;
    }
};

// A paged scene's page caches (geometry, attributes, textures): their
// state after the last pass, with the counts (requests, hits, bytes read,
// evictions, ...) of that pass alone.
struct PagedStatus {
    std::vector<PageCacheReport> caches;  // empty for an in-core scene
    size_t cache_bytes = 0;      // the caches' memory together
    size_t budget_bytes = 0;     // their budgets together
    size_t resident_bytes = 0;   // the always-resident levels (grid, middle BVHs, tables), outside the budget
};

// An animated scene's playback (Session::play, Session::set_time).
struct AnimationStatus {
    bool animated = false;       // the shown scene has an animation
    float start = 0.0f, end = 0.0f, frames_per_second = 30.0f;
    float time = 0.0f;           // the time rendered
    bool playing = false;
    std::string method;          // the structure's update method
    UpdateStats last;            // the last update
    double mean_update_ms = 0.0; // over the updates since playback started
    uint64_t updates = 0;
};

struct SessionStatus {
    // The scene shown (empty before the first one is ready).
    std::string scene_name;
    size_t triangles = 0;
    double load_ms = 0.0;
    // The job running, if any.
    bool busy = false;
    std::string job;             // "loading sponza", "building bvh/sbvh/bvh8"
    double job_progress = 0.0;   // 0..1
    double job_seconds = 0.0;
    // The structure rendering now (a paged scene's: the resident levels).
    AccelStats accel;
    PagedStatus paged;
    // The last error (a failed load, build or setting), and how many so far.
    std::string error;
    uint64_t error_count = 0;
    int motion_divisor = 2;      // in use for previews
    double full_pass_ms = 0.0;   // the last full-resolution pass
    AnimationStatus animation;
};

// Runs on the job thread for every world opened, before its structure is
// built and it is shown (adds lights, picks the start camera in
// data.camera); `first` is true for the first scene, whose file may also set
// `settings` (its render settings: size, integrator, depths). May throw
// rf::Error, which fails the load.
using PrepareScene = std::function<void(World& world, SceneData& data, bool first, ViewSettings& settings)>;

struct SessionConfig {
    ViewSettings settings;  // settings.world: the device, structure, update method and paged budgets
    PrepareScene prepare;
    // Run the session's threads (and the TBB workers they start) at a lower
    // priority than the caller's, so a window stays responsive while they
    // fill the cores.
    bool yield_to_window = false;
    // How the first scene loads (--animation: its glTF clip); later scenes load with the defaults.
    LoadOptions first_load;
};

class Session {
public:
    explicit Session(SessionConfig config);
    ~Session();
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;

    // Loads and builds in the background; on success the scene replaces the
    // shown one, on failure the error is reported and the old scene stays.
    void load(const SceneSource& source);
    // New settings: a structure rebuild in the background, a restart, or a
    // new tone mapping, as changes_between says. Values are assumed checked
    // (set_setting).
    void set_settings(const ViewSettings& settings);
    // A camera for scene `scene_id` (requests for another scene are
    // dropped). `moving`: render previews; false: accumulate at full
    // resolution. `asked` is when the change was made (latency statistics).
    void set_camera(const Camera& camera, uint64_t scene_id, bool moving, Clock::time_point asked = Clock::now());

    // Animated scenes: play (time advances with the wall clock, looping at
    // the end, the structure updated each frame by the settings' update
    // method) or pause; set_time shows one time (scrubbing) and pauses.
    void play(bool playing);
    void set_time(float t);

    [[nodiscard]] std::shared_ptr<const Frame> frame() const;
    [[nodiscard]] std::shared_ptr<const SceneData> scene() const;
    [[nodiscard]] SessionStatus status() const;
    [[nodiscard]] ViewSettings settings() const;
    [[nodiscard]] Versions versions() const;
    // The current film's mean (linear radiance), read by the render thread
    // between passes; empty before the first renderer.
    std::future<Image> film();
    // Called (from the session's threads) whenever a frame or the status
    // changes, so a waiting window can wake up.
    void set_wake(std::function<void()> wake);

private:
    struct Target;  // a world built, ready to render
    struct RenderState;
    struct RenderRequests;

    void job_loop();
    void render_loop();
    bool take_requests(RenderState& st, RenderRequests& r);
    void apply_requests(RenderState& st, const RenderRequests& r);
    bool run_pass(RenderState& st);
    void publish_frame(RenderState& st);
    void run_load(const SceneSource& source);
    void run_build(const WorldOptions& options);
    void hand_over(Target target);
    void advance_animation(RenderState& st, bool time_requested);
    void report_error(const std::string& message);
    void wake();

    SessionConfig config_;
    mutable std::mutex mutex_;
    std::condition_variable render_cv_, job_cv_;
    bool stopping_ = false;

    // Job thread requests.
    std::optional<SceneSource> queued_load_;
    std::optional<WorldOptions> queued_build_;
    bool first_load_ = true;
    uint64_t next_scene_id_ = 1;

    // Render thread requests (the latest of each kind).
    std::shared_ptr<const SceneData> shown_scene_;   // what the render thread draws or is about to
    std::shared_ptr<World> shown_world_;             // its world: what a structure change reopens
    std::shared_ptr<const Target> new_target_;
    ViewSettings settings_;
    uint64_t settings_version_ = 0;
    uint64_t target_version_ = 0;
    unsigned pending_effects_ = 0;                   // Restart | Retone not yet applied
    Camera camera_;
    uint64_t camera_version_ = 0, applied_camera_version_ = 0;
    Clock::time_point camera_time_;
    bool moving_ = false;
    std::vector<std::promise<Image>> film_requests_;
    bool playing_ = false;
    float time_request_ = 0.0f;
    uint64_t time_version_ = 0;
    std::atomic<bool> cancel_{false};
    std::atomic<bool> pass_is_preview_{false};

    // Published.
    std::shared_ptr<const Frame> frame_;
    SessionStatus status_;
    std::function<void()> wake_;

    std::thread job_thread_, render_thread_;
};

}  // namespace rf::viewer
