#include "session.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <new>
#include <utility>

#include "elapsed.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

namespace rf::viewer {
namespace {

constexpr double kPreviewTargetMs = 30.0;  // a preview pass this long keeps motion above 30 frames per second
constexpr size_t kDisplayImages = 3;       // the window's, the published one, and one to fill
constexpr int kEngineNice = 5;             // CFS weight 335 against the window's 1024

// The engine's threads yield to the window's: a nice value above the
// window thread's, so on a machine whose cores the renderer and a build
// fill, the window still gets the CPU it needs for each frame when it needs
// it. TBB's workers are started by these threads and inherit it. (Linux
// gives each thread its own nice value; elsewhere this does nothing.)
void yield_to_the_window() {
#if defined(__linux__)
    (void)setpriority(PRIO_PROCESS, pid_t(syscall(SYS_gettid)), kEngineNice);
#endif
}

// What one pass did to a cache: `after`'s state with the counts since `before`.
PageCacheReport pass_counts(const PageCacheReport& after, const PageCacheReport& before) {
    const auto since = [](auto a, auto b) { return a >= b ? a - b : a; };  // a reset in between: all of a
    PageCacheReport r = after;
    r.requests = since(after.requests, before.requests);
    r.hits = since(after.hits, before.hits);
    r.misses = since(after.misses, before.misses);
    r.pages_read = since(after.pages_read, before.pages_read);
    r.bytes_read = since(after.bytes_read, before.bytes_read);
    r.evictions = since(after.evictions, before.evictions);
    r.swaps = since(after.swaps, before.swaps);
    r.io_ms = since(after.io_ms, before.io_ms);
    r.manage_ms = since(after.manage_ms, before.manage_ms);
    return r;
}

// A paged scene's caches now, with the counts since `before` (the caches
// as they were when the pass began; empty: all counts so far).
PagedStatus paged_status(const PagedScene& scene, const std::vector<PageCacheReport>& before) {
    PagedStatus status;
    status.caches = scene.caches();
    for (size_t i = 0; i < status.caches.size(); ++i) {
        PageCacheReport& c = status.caches[i];
        if (i < before.size()) c = pass_counts(c, before[i]);
        status.cache_bytes += c.memory_bytes;
        status.budget_bytes += c.budget_bytes;
    }
    status.resident_bytes = scene.info().resident_bytes;
    return status;
}

}  // namespace

struct Session::Target {
    std::shared_ptr<const SceneData> scene;
    std::shared_ptr<World> world;  // committed: its structure is built
};

// What the render thread holds.
struct Session::RenderState {
    std::shared_ptr<const Target> target;
    std::unique_ptr<Renderer> renderer;
    ViewSettings settings;
    uint64_t settings_version = 0;
    uint64_t target_version = 0;
    Camera camera;
    uint64_t camera_version = 0;
    Clock::time_point camera_time;
    bool moving = false;          // the renderer is set up for previews
    bool preview_done = false;    // this camera's preview is published
    bool halted = false;          // a pass failed: wait for a change
    int motion_divisor = 2;
    double full_pass_ms = 0.0;
    uint64_t sequence = 0;
    std::vector<std::shared_ptr<DisplayImage>> pool;
    std::vector<PageCacheReport> caches_before;  // a paged target's caches when the pass began
    PagedStatus paged;                           // and after its last pass (empty in core)
    bool playing = false;                        // an animated target's time advances
    float requested_time = 0.0f;
    uint64_t time_version = 0;
    Clock::time_point last_tick;                 // when the animation's time last advanced

    [[nodiscard]] bool animating() const { return playing && target && target->world->animated() && !halted; }
    [[nodiscard]] bool wants_pass() const {
        if (!renderer || halted) return false;
        if (animating()) return true;
        return moving ? !preview_done : renderer->passes() < renderer->options().spp;
    }
    // The film's options (the renderer runs where its world lives).
    [[nodiscard]] RenderOptions film() const { return film_options(settings, moving, motion_divisor); }
    // A display image no frame holds (the pool's reference is its only one).
    std::shared_ptr<DisplayImage> free_image() {
        for (const auto& image : pool)
            if (image.use_count() == 1) return image;
        pool.push_back(std::shared_ptr<DisplayImage>(renderer->make_display_image()));
        if (pool.size() > kDisplayImages) pool.erase(pool.begin());  // only when the window holds on to old frames
        return pool.back();
    }
};

Session::Session(SessionConfig config) : config_(std::move(config)), settings_(config_.settings) {
    job_thread_ = std::thread([this] { job_loop(); });
    render_thread_ = std::thread([this] { render_loop(); });
}

Session::~Session() {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        stopping_ = true;
        cancel_.store(true);
    }
    render_cv_.notify_all();
    job_cv_.notify_all();
    job_thread_.join();  // a build under way finishes first: builders cannot be interrupted
    render_thread_.join();
}

void Session::set_wake(std::function<void()> wake) {
    std::lock_guard<std::mutex> lock(mutex_);
    wake_ = std::move(wake);
}

void Session::wake() {
    std::function<void()> wake;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        wake = wake_;
    }
    if (wake) wake();
}

void Session::report_error(const std::string& message) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        status_.error = message;
        ++status_.error_count;
    }
    wake();
}

// ---- requests from the window's thread

void Session::load(const SceneSource& source) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        queued_load_ = source;
        queued_build_.reset();  // the load builds with the latest settings
    }
    job_cv_.notify_one();
}

void Session::set_settings(const ViewSettings& settings) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        const unsigned effects = changes_between(settings_, settings);
        if (effects == 0) return;
        settings_ = settings;
        ++settings_version_;
        unsigned now = effects & (unsigned(Effect::Restart) | unsigned(Effect::Retone));
        if (effects & unsigned(Effect::Rebuild)) {
            if (!queued_load_) queued_build_ = settings.world;
            job_cv_.notify_one();
            // A paged scene has no structure to rebuild (the job thread skips
            // it; the settings table refuses such changes for one): its frame
            // only has to show the new settings.
            if (shown_scene_ && shown_scene_->kind == SceneKind::Paged) now |= unsigned(Effect::Retone);
        }
        if (now) {
            pending_effects_ |= now;
            cancel_.store(true);
        }
    }
    render_cv_.notify_one();
}

void Session::set_camera(const Camera& camera, uint64_t scene_id, bool moving, Clock::time_point asked) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        if (!shown_scene_ || shown_scene_->id != scene_id) return;  // meant for a scene being replaced
        camera_ = camera;
        moving_ = moving;
        camera_time_ = asked;
        ++camera_version_;
        // A preview pass is short and shows motion: let it finish.
        if (!pass_is_preview_.load()) cancel_.store(true);
    }
    render_cv_.notify_one();
}

void Session::play(bool playing) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        playing_ = playing;
        status_.animation.playing = playing && status_.animation.animated;
        status_.animation.updates = 0;
        status_.animation.mean_update_ms = 0.0;
    }
    render_cv_.notify_one();
}

void Session::set_time(float t) {
    {
        std::lock_guard<std::mutex> lock(mutex_);
        playing_ = false;
        status_.animation.playing = false;
        time_request_ = t;
        ++time_version_;
        cancel_.store(true);
    }
    render_cv_.notify_one();
}

std::future<Image> Session::film() {
    std::future<Image> result;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        film_requests_.emplace_back();
        result = film_requests_.back().get_future();
    }
    render_cv_.notify_one();
    return result;
}

std::shared_ptr<const Frame> Session::frame() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return frame_;
}

std::shared_ptr<const SceneData> Session::scene() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return shown_scene_;
}

ViewSettings Session::settings() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return settings_;
}

Versions Session::versions() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return {camera_version_, settings_version_, target_version_, time_version_,
            status_.busy || queued_load_ || queued_build_};
}

SessionStatus Session::status() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return status_;
}

// ---- the job thread

void Session::job_loop() {
    if (config_.yield_to_window) yield_to_the_window();
    for (;;) {
        std::optional<SceneSource> load;
        std::optional<WorldOptions> build;
        std::shared_ptr<const SceneData> scene;
        {
            std::unique_lock<std::mutex> lock(mutex_);
            job_cv_.wait(lock, [&] { return stopping_ || queued_load_ || queued_build_; });
            if (stopping_) return;
            if (queued_load_) load = std::exchange(queued_load_, std::nullopt);
            else build = std::exchange(queued_build_, std::nullopt);
            scene = shown_scene_;
            status_.busy = true;
            status_.job_progress = 0.0;
        }
        const Clock::time_point start = Clock::now();
        try {
            if (load) run_load(*load);
            else if (scene && scene->kind != SceneKind::Paged) run_build(*build);
        } catch (const Error& e) {
            report_error(e.what());
        } catch (const std::bad_alloc&) {
            report_error(load ? load->name + ": out of memory while loading" : "out of memory while building");
        }
        {
            std::lock_guard<std::mutex> lock(mutex_);
            status_.busy = queued_load_ || queued_build_;
            status_.job_seconds = ms_since(start) * 1e-3;
        }
        wake();
    }
}

namespace {

// Reports a job's name and progress into the status.
class JobProgress {
public:
    JobProgress(std::mutex& mutex, SessionStatus& status, const std::function<void()>& wake, std::string job)
        : mutex_(mutex), status_(status), wake_(wake), start_(Clock::now()) {
        std::lock_guard<std::mutex> lock(mutex_);
        status_.job = std::move(job);
        status_.job_progress = 0.0;
        status_.job_seconds = 0.0;
    }
    void operator()(double fraction) {
        {
            std::lock_guard<std::mutex> lock(mutex_);
            status_.job_progress = fraction;
            status_.job_seconds = ms_since(start_) * 1e-3;
        }
        if (wake_) wake_();
    }

private:
    std::mutex& mutex_;
    SessionStatus& status_;
    const std::function<void()>& wake_;
    Clock::time_point start_;
};

std::string structure_name(const BuildOptions& o) {
    if (o.structure != Structure::Bvh) return to_string(o.structure);
    return "bvh/" + to_string(o.builder) + (o.reinsertion.enabled ? "+opt" : "") + "/" + to_string(o.layout);
}

}  // namespace

void Session::run_load(const SceneSource& source) {
    std::function<void()> wake;
    bool first = false;
    ViewSettings settings;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        wake = wake_;
        first = first_load_;
        settings = settings_;
    }
    auto data = std::make_shared<SceneData>();
    data->source = source;
    std::shared_ptr<World> world;
    {
        JobProgress progress(mutex_, status_, wake, "loading " + source.name);
        progress(0.0);
        world = open_world(source.path, settings.world, first ? config_.first_load : LoadOptions{});
    }
    const WorldStats loaded = world->stats();
    if (loaded.triangles == 0) throw Error(source.name + ": the scene has no triangles to show");
    data->kind = world->paged() ? SceneKind::Paged : SceneKind::InCore;
    data->load_ms = loaded.load_ms;
    data->triangles = size_t(loaded.triangles);
    data->size = length(world->bounds().extent());
    data->camera = source.views.empty() ? world->camera() : source.views.front();
    if (config_.prepare) {
        const ViewSettings before = settings;
        config_.prepare(*world, *data, first, settings);
        if (changes_between(before, settings) != 0) {
            std::lock_guard<std::mutex> lock(mutex_);
            settings_ = settings;
            ++settings_version_;
            pending_effects_ |= unsigned(Effect::Restart);
        }
    }
    {
        std::lock_guard<std::mutex> lock(mutex_);
        data->id = next_scene_id_++;
        first_load_ = false;
    }
    JobProgress progress(mutex_, status_, wake,
                         "building " + structure_name(settings.world.build) + " for " + source.name);
    world->commit(std::ref(progress));  // a paged world's structure came with its file
    hand_over(Target{std::move(data), std::move(world)});
}

// The shown world reopened with new options: its scene at the time it
// shows, another structure, update method or device.
void Session::run_build(const WorldOptions& options) {
    std::function<void()> wake;
    std::shared_ptr<const SceneData> data;
    std::shared_ptr<World> shown;
    {
        std::lock_guard<std::mutex> lock(mutex_);
        wake = wake_;
        data = shown_scene_;
        shown = shown_world_;
    }
    if (!shown) return;
    JobProgress progress(mutex_, status_, wake, "building " + structure_name(options.build));
    std::shared_ptr<World> world = shown->reopen(options);
    world->commit(std::ref(progress));
    {
        std::lock_guard<std::mutex> lock(mutex_);
        // A newer request makes this structure stale before it is shown.
        if (queued_load_ || queued_build_ || shown_scene_ != data) return;
    }
    hand_over(Target{std::move(data), std::move(world)});
}

void Session::hand_over(Target target) {
    // Outside the lock: a structure may compute its statistics (a kd-tree's
    // SAH cost walks the tree), and the window reads the status every frame.
    std::shared_ptr<const SceneData> data = target.scene;
    const World& world = *target.world;
    const WorldStats stats = world.stats();
    const TimeRange range = world.time_range();
    {
        std::lock_guard<std::mutex> lock(mutex_);
        status_.accel = stats.accel;
        AnimationStatus& a = status_.animation;
        if (world.animated()) {
            a.time = world.time();
            a.animated = true;
            a.start = range.start;
            a.end = range.end;
            a.frames_per_second = range.frames_per_second;
            a.method = stats.update_method;
            a.playing = playing_;
        } else {
            a = AnimationStatus{};
        }
        if (shown_scene_ != data) {
            shown_scene_ = data;
            camera_ = data->camera;
            moving_ = false;
            camera_time_ = Clock::now();
            ++camera_version_;
            status_.scene_name = data->source.name;
            status_.triangles = data->triangles;
            status_.load_ms = data->load_ms;
        }
        shown_world_ = target.world;
        new_target_ = std::make_shared<const Target>(std::move(target));
        ++target_version_;
        cancel_.store(true);
    }
    render_cv_.notify_one();
    wake();
}

// ---- the render thread

// What the render thread took from the requests at the top of a round.
struct Session::RenderRequests {
    std::shared_ptr<const Target> target;  // a new scene or structure
    unsigned effects = 0;                  // Restart | Retone
    bool camera_changed = false;
    bool was_moving = false;
    bool time_requested = false;
    std::vector<std::promise<Image>> films;
};

void Session::render_loop() {
    if (config_.yield_to_window) yield_to_the_window();
    RenderState st;
    RenderRequests r;
    while (take_requests(st, r)) {
        apply_requests(st, r);
        advance_animation(st, r.time_requested);
        for (std::promise<Image>& film : r.films) film.set_value(st.renderer ? st.renderer->image() : Image{});
        if (!r.films.empty()) wake();
        bool publish = st.renderer && (r.effects & unsigned(Effect::Retone)) && st.renderer->passes() > 0;
        if (st.wants_pass()) {
            if (!run_pass(st)) continue;  // cancelled (something changed) or failed
            publish = true;
        }
        if (publish) publish_frame(st);
    }
}

// Waits until there is something to do; false when the session stops.
bool Session::take_requests(RenderState& st, RenderRequests& r) {
    r = RenderRequests{};
    r.was_moving = st.moving;
    std::unique_lock<std::mutex> lock(mutex_);
    render_cv_.wait(lock, [&] {
        return stopping_ || new_target_ || pending_effects_ || camera_version_ != st.camera_version ||
               !film_requests_.empty() || time_version_ != st.time_version || playing_ != st.playing ||
               st.wants_pass();
    });
    if (stopping_) return false;
    cancel_.store(false);
    r.target = std::exchange(new_target_, nullptr);
    if (r.target) st.target_version = target_version_;
    r.effects = std::exchange(pending_effects_, 0u);
    r.films = std::exchange(film_requests_, {});
    st.settings = settings_;
    st.settings_version = settings_version_;
    if (playing_ && !st.playing) st.last_tick = Clock::now();
    st.playing = playing_;
    if (time_version_ != st.time_version) {
        r.time_requested = true;
        st.requested_time = time_request_;
        st.time_version = time_version_;
    }
    if (camera_version_ != st.camera_version) {
        r.camera_changed = true;
        st.camera = camera_;
        st.camera_version = camera_version_;
        st.camera_time = camera_time_;
        st.moving = moving_;
        st.preview_done = false;
    }
    if (r.target || r.effects || r.camera_changed || r.time_requested) st.halted = false;
    if (st.moving && !r.was_moving)  // a motion starts: size its previews
        st.motion_divisor = st.settings.motion_divisor > 0 ? st.settings.motion_divisor
                                                           : auto_motion_divisor(st.full_pass_ms, kPreviewTargetMs);
    status_.motion_divisor = st.motion_divisor;
    return true;
}

// A new target gets a new renderer (if that fails, the old one keeps
// rendering); otherwise the camera and the film's options are brought up to date.
void Session::apply_requests(RenderState& st, const RenderRequests& r) {
    try {
        if (r.target) {
            std::unique_ptr<Renderer> renderer = make_renderer(*r.target->world, st.camera, st.film());
            st.renderer = std::move(renderer);
            st.target = r.target;
            st.pool.clear();
            st.paged = r.target->world->paged() ? paged_status(r.target->world->paged_scene(), {}) : PagedStatus{};
            std::lock_guard<std::mutex> lock(mutex_);
            status_.paged = st.paged;
            return;
        }
        if (!st.renderer) return;
        if (r.camera_changed) st.renderer->set_camera(st.camera);
        const RenderOptions film = st.film();
        if ((r.effects & unsigned(Effect::Restart)) || st.moving != r.was_moving ||
            st.renderer->options().width != film.width || st.renderer->options().height != film.height)
            st.renderer->set_options(film);
    } catch (const Error& e) {
        report_error(e.what());
    }
}

// An animated world at the requested time, or, while playing, at the time
// the wall clock has advanced to (looping at the end); its renderer follows
// it at the next pass.
void Session::advance_animation(RenderState& st, bool time_requested) {
    if (!st.renderer || !st.target || !st.target->world->animated() || st.halted) return;
    World& world = *st.target->world;
    const TimeRange range = world.time_range();
    float t = world.time();
    if (time_requested) {
        t = std::clamp(st.requested_time, range.start, range.end);
    } else if (st.playing) {
        const Clock::time_point now = Clock::now();
        t += float(std::chrono::duration<double>(now - st.last_tick).count());
        st.last_tick = now;
        const float duration = range.end - range.start;
        if (t > range.end) t = duration > 0.0f ? range.start + std::fmod(t - range.start, duration) : range.start;
    } else {
        return;
    }
    try {
        const UpdateStats u = world.set_time(t);
        std::lock_guard<std::mutex> lock(mutex_);
        AnimationStatus& s = status_.animation;
        s.time = t;
        if (!u.updated) return;
        s.last = u;
        ++s.updates;
        s.mean_update_ms += (u.update_ms - s.mean_update_ms) / double(s.updates);
    } catch (const Error& e) {
        st.halted = true;
        report_error(e.what());
    }
}

// One pass; false when it was cancelled or failed (a failure halts passes
// until the next change).
bool Session::run_pass(RenderState& st) {
    pass_is_preview_.store(st.moving);
    PagedScene* paged = st.target->world->paged() ? &st.target->world->paged_scene() : nullptr;
    try {
        if (paged) st.caches_before = paged->caches();
        if (!st.renderer->render_pass({}, &cancel_)) return false;
    } catch (const Error& e) {
        st.halted = true;
        report_error(e.what());
        return false;
    }
    if (paged) st.paged = paged_status(*paged, st.caches_before);
    if (st.moving) st.preview_done = true;
    else st.full_pass_ms = st.renderer->last_pass().pass_ms;
    return true;
}

// The renderer's image into a free display image, published as the newest Frame.
void Session::publish_frame(RenderState& st) {
    try {
        std::shared_ptr<DisplayImage> image = st.free_image();
        st.renderer->update_display(*image, st.settings.tone);
        const PassStats& pass = st.renderer->last_pass();
        auto frame = std::make_shared<Frame>();
        frame->image = image;
        frame->sequence = ++st.sequence;
        frame->passes = st.renderer->passes();
        frame->target_passes = st.renderer->options().spp;
        frame->preview = st.moving;
        frame->pass_ms = pass.pass_ms;
        frame->pass_rays = pass.closest_rays + pass.shadow_rays;
        frame->camera_version = st.camera_version;
        frame->camera_time = st.camera_time;
        frame->settings_version = st.settings_version;
        frame->target_version = st.target_version;
        frame->time_version = st.time_version;
        {
            std::lock_guard<std::mutex> lock(mutex_);
            frame_ = std::move(frame);
            status_.full_pass_ms = st.full_pass_ms;
            status_.paged = st.paged;
        }
        wake();
    } catch (const Error& e) {
        st.halted = true;
        report_error(e.what());
    }
}

}  // namespace rf::viewer
