#include "viewer_app.h"

#include <stb_image_write.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <thread>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "script_runner.h"

namespace rf::viewer {
namespace {

constexpr double kTickSeconds = 1.0 / 60.0;   // the loop's rate while something moves
constexpr double kIdleWaitSeconds = 0.5;      // the longest wait for an event otherwise

double seconds_between(Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
}

SceneKind kind_of(const SceneSource& source) {
    return is_paged_scene_file(source.path) ? SceneKind::Paged : SceneKind::InCore;
}

std::vector<std::string> usable_devices() {
    std::vector<std::string> devices{"cpu"};
    for (const DeviceInfo& d : list_cuda_devices().devices) devices.push_back("cuda:" + std::to_string(d.index));
    return devices;
}

}  // namespace

App::App(const ViewerConfig& config, GlWindow& window)
    : config_(config), window_(window), catalog_(SceneCatalog::discover(config.scenes_dir)),
      settings_(config.settings), devices_(usable_devices()) {
    if (config.script) script_ = std::make_unique<ScriptRunner>(*config.script, config.script_timeout_s);
    std::error_code ec;
    if (!config.bookmarks.empty() && std::filesystem::exists(config.bookmarks, ec)) {
        try {
            bookmarks_ = Bookmarks::load(config.bookmarks);
        } catch (const Error& e) {
            show_message(e.what(), true);
        }
    }
    if (!catalog_.problem.empty()) show_message(catalog_.problem, true);
    const SceneSource first = catalog_.resolve(config.scene);  // a name that names nothing fails the start
    SessionConfig session;
    session.settings = settings_;
    session.prepare = config.prepare;
    session.yield_to_window = true;
    session.first_load = config.first_load;
    session_ = std::make_unique<Session>(std::move(session));
    session_->set_wake([] { GlWindow::wake(); });
    loading_kind_ = kind_of(first);
    session_->load(first);
}

App::~App() {
    // The session joins its threads; a build under way cannot be interrupted.
    if (session_ && session_->status().busy)
        std::fprintf(stderr, "rayforge: viewer: waiting for \"%s\" to finish\n", session_->status().job.c_str());
}

int App::run() {
    last_tick_ = Clock::now();
    while (!quit_ && !window_.should_close()) {
        window_.wait_events(wait_budget(Clock::now()));
        const Clock::time_point now = Clock::now();
        last_tick_ = now;
        frame(now);
        // The window's own work, waits excluded: what a blocked window would show.
        stats_.ui_frame_done(std::chrono::duration<double, std::milli>(Clock::now() - now).count());
    }
    // Screenshots asked for just before the end are still written.
    for (PendingShot& shot : shots_) shot.film.wait();
    finish_screenshots();
    return exit_status_;
}

// How long the loop may wait for an event: a tick while something moves by
// itself (a held walk key, a scripted walk), until the motion rests or a
// script's sleep ends, and otherwise until the session or the user wakes it.
double App::wait_budget(Clock::time_point now) const {
    const double tick = std::max(0.0, kTickSeconds - seconds_between(last_tick_, now));
    if (walking_ || (script_ && script_->wants_ticks())) return tick;
    double wait = kIdleWaitSeconds;
    if (moving_) wait = std::min(wait, std::max(tick, kRestSeconds - seconds_between(last_move_, now)));
    if (script_ && !script_->finished()) wait = std::min(wait, std::max(0.0, script_->seconds_to_deadline(now)));
    return wait;
}

void App::frame(Clock::time_point now) {
    stats_.ui_frames.add(now);
    for (const std::string& path : window_.take_dropped()) drop(path);
    follow_session(now);
    window_.begin_frame();
    if (has_scene()) handle_input(now);
    if (script_ && !script_->finished()) {
        script_->step(*this, now);
        if (script_->finished()) quit(script_->failed() ? 1 : 0);
    }
    if (moving_ && seconds_between(last_move_, now) >= kRestSeconds) end_motion(now);
    finish_screenshots();

    int width = 0, height = 0;
    window_.framebuffer_size(width, height);
    film_.draw(float(width), float(height));
    if (panel_visible_) draw_panel();
    draw_overlay(now);
    draw_messages(now);
    window_.end_frame();
    for (auto& [path, done] : window_shots_) {
        int w = 0, h = 0;
        const std::vector<unsigned char> rgba = window_.read_back(w, h);
        const bool ok = stbi_write_png(path.c_str(), w, h, 4, rgba.data(), w * 4) != 0;
        const std::string error = ok ? "" : path + ": cannot write PNG file";
        show_message(ok ? "saved " + path : error, !ok);
        if (done) done(error);
    }
    window_shots_.clear();
    window_.swap();
}

// New frames, a new scene, new errors.
void App::follow_session(Clock::time_point now) {
    if (!session_->versions().jobs_pending) loading_kind_.reset();  // loaded or failed: the shown scene decides
    const std::shared_ptr<const SceneData> scene = session_->scene();
    if (scene && scene->id != scene_id_) adopt_scene(scene);
    follow_errors();
    const std::shared_ptr<const Frame> latest = session_->frame();
    if (!latest || (shown_ && latest->sequence == shown_->sequence)) return;
    film_.show(*latest->image);
    const bool first_of_camera = latest->camera_version != last_camera_version_shown_;
    last_camera_version_shown_ = latest->camera_version;
    if (stats_.first_image_ms < 0.0)
        stats_.first_image_ms = std::chrono::duration<double, std::milli>(now - config_.launched).count();
    stats_.frame_shown(*latest, now, first_of_camera);
    shown_ = latest;
}

void App::follow_errors() {
    const SessionStatus status = session_->status();
    if (status.error_count == session_errors_) return;
    session_errors_ = status.error_count;
    show_message(status.error, true);
}

void App::adopt_scene(const std::shared_ptr<const SceneData>& scene) {
    if (scene_id_ == 0) settings_ = session_->settings();  // the first scene's file may have set some
    scene_id_ = scene->id;
    controller_ = std::make_unique<CameraController>(scene->camera, scene->size);
    moving_ = false;
    scene_views_.clear();
    for (size_t i = 0; i < scene->source.views.size(); ++i)
        scene_views_.push_back({"view " + std::to_string(i + 1), scene->source.name, scene->source.views[i]});
    window_.set_title("rayforge view - " + scene->source.name);
}

bool App::scene_adopted() const {
    const std::shared_ptr<const SceneData> scene = session_->scene();
    return scene && scene->id == scene_id_;
}

void App::camera_moved() {
    if (!has_scene()) return;
    moving_ = true;
    last_move_ = Clock::now();
    session_->set_camera(controller_->camera(), scene_id_, true, last_move_);
}

void App::camera_placed() {
    if (!has_scene()) return;
    moving_ = false;
    session_->set_camera(controller_->camera(), scene_id_, false);
}

void App::end_motion(Clock::time_point now) {
    moving_ = false;
    session_->set_camera(controller_->camera(), scene_id_, false, now);
}

void App::reset_camera() {
    if (!has_scene()) return;
    controller_->reset();
    camera_placed();
}

void App::set(const std::string& key, const std::string& value) {
    set_setting(settings_, key, value, scene_kind());
    session_->set_settings(settings_);
}

SceneKind App::scene_kind() const {
    if (loading_kind_) return *loading_kind_;
    const std::shared_ptr<const SceneData> scene = session_->scene();
    return scene ? scene->kind : SceneKind::InCore;
}

void App::load(const std::string& name_or_path) {
    const SceneSource source = catalog_.resolve(name_or_path);
    loading_kind_ = kind_of(source);
    session_->load(source);
}

void App::drop(const std::string& path) {
    try {
        load(path);
        show_message("loading " + path, false);
    } catch (const Error& e) {
        show_message(e.what(), true);
    }
}

void App::save_bookmark(const std::string& name) {
    if (!has_scene()) throw Error("bookmark " + name + ": no scene is shown yet");
    const std::shared_ptr<const SceneData> scene = session_->scene();
    bookmarks_.put({name, scene ? scene->source.name : "", controller_->camera()});
    save_bookmarks_file();
}

void App::load_bookmark(const std::string& name) {
    const Bookmark* b = bookmarks_.find(name);
    for (const Bookmark& view : scene_views_)
        if (!b && view.name == name) b = &view;
    if (!b) throw Error("no bookmark named '" + name + "'");
    if (!has_scene()) throw Error("bookmark " + name + ": no scene is shown yet");
    controller_->set(b->camera);
    camera_placed();
}

void App::remove_bookmark(const std::string& name) {
    if (bookmarks_.remove(name)) save_bookmarks_file();
}

void App::save_bookmarks_file() {
    if (config_.bookmarks.empty()) return;
    try {
        bookmarks_.save(config_.bookmarks);
        show_message("bookmarks saved to " + config_.bookmarks, false);
    } catch (const Error& e) {
        show_message(e.what(), true);
    }
}

void App::screenshot(const std::string& path, std::function<void(const std::string&)> done) {
    shots_.push_back({path, session_->film(), settings_.tone, std::move(done)});
}

void App::screenshot_now() {
    const std::string stem = "rayforge-" + timestamp() + "-" + std::to_string(++screenshot_counter_);
    screenshot(stem + ".png");
    screenshot(stem + ".exr");
}

void App::screenshot_window(const std::string& path, std::function<void(const std::string&)> done) {
    window_shots_.emplace_back(path, std::move(done));
}

void App::finish_screenshots() {
    for (auto it = shots_.begin(); it != shots_.end();) {
        if (it->film.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
            ++it;
            continue;
        }
        std::string error;
        try {
            const Image film = it->film.get();
            if (film.width == 0) throw Error(it->path + ": nothing rendered yet");
            write_image(it->path, film, it->tone);
            show_message("saved " + it->path, false);
        } catch (const std::exception& e) {
            error = e.what();
            show_message(error, true);
        }
        if (it->done) it->done(error);
        it = shots_.erase(it);
    }
}

void App::quit(int status) {
    quit_ = true;
    exit_status_ = std::max(exit_status_, status);
}

void App::show_message(const std::string& text, bool error) {
    message_ = text;
    message_is_error_ = error;
    message_time_ = Clock::now();
    if (error) {
        error_text_ = text;
        ++errors_seen_;
        std::fprintf(stderr, "rayforge: viewer: %s\n", text.c_str());
    }
}

std::string App::timestamp() {
    char text[32];
    const std::time_t t = std::time(nullptr);
    std::tm local{};
    localtime_r(&t, &local);
    std::strftime(text, sizeof text, "%Y%m%d-%H%M%S", &local);
    return text;
}

std::string App::stats_json() { return stats_.json(session_->status(), Clock::now()); }

}  // namespace rf::viewer
