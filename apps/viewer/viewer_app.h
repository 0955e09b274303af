// The viewer's window loop and everything a person (or a script) can do in
// it. The loop: read input, step the script, tell the session about camera
// and setting changes, show the newest frame, draw the panel and the
// statistics overlay. It waits for events when nothing moves, so the
// renderer keeps the cores.
#pragma once

#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bookmarks.h"
#include "camera_controller.h"
#include "film_view.h"
#include "gl_window.h"
#include "scene_catalog.h"
#include "script.h"
#include "session.h"
#include "viewer.h"
#include "viewer_stats.h"

namespace rf::viewer {

class ScriptRunner;

class App {
public:
    App(const ViewerConfig& config, GlWindow& window);
    ~App();
    int run();  // until the window closes or quit(); the exit status

    // ---- what input, the panel and scripts do
    [[nodiscard]] CameraController& controller() { return *controller_; }
    [[nodiscard]] bool has_scene() const { return controller_ != nullptr; }
    // The window shows the session's newest scene (it adopts a new one at the start of a frame).
    [[nodiscard]] bool scene_adopted() const;
    // The controller's camera changed by a motion (drag, wheel, walk):
    // previews until it rests for kRestSeconds.
    void camera_moved();
    // The controller's camera jumped (reset, bookmark, typed camera): full
    // resolution at once.
    void camera_placed();
    void reset_camera();
    // Throws rf::Error for an unknown key, a bad value, or a setting the
    // shown scene does not take (structure settings of a paged scene).
    void set(const std::string& key, const std::string& value);
    // In core or paged: the scene a pending load was asked for, else the
    // session's newest scene (before any, in core). Settings typed right
    // after a load are checked for the scene they will apply to.
    [[nodiscard]] SceneKind scene_kind() const;
    // A views.json name, a file or builtin:NAME; throws rf::Error when it names nothing.
    void load(const std::string& name_or_path);
    // As a file dropped onto the window: failures become the window's error line.
    void drop(const std::string& path);
    void save_bookmark(const std::string& name);
    void load_bookmark(const std::string& name);  // throws rf::Error when there is none
    void remove_bookmark(const std::string& name);
    // PNG: the displayed image (the film tone-mapped as shown); EXR/PFM:
    // the linear film. Written once the render thread hands over the film;
    // `done` gets "" or the error.
    void screenshot(const std::string& path, std::function<void(const std::string&)> done = {});
    // The F12 key and the panel's button: a PNG and an EXR named by the time.
    void screenshot_now();
    // The window as drawn (panel included), after this frame; PNG.
    void screenshot_window(const std::string& path, std::function<void(const std::string&)> done = {});
    void quit(int status);
    void show_message(const std::string& text, bool error);

    [[nodiscard]] Session& session() { return *session_; }
    [[nodiscard]] const ViewSettings& settings() const { return settings_; }
    [[nodiscard]] ViewerStats& stats() { return stats_; }
    [[nodiscard]] std::shared_ptr<const Frame> shown_frame() const { return shown_; }
    [[nodiscard]] bool moving() const { return moving_; }
    // Takes the session's newest error into the window's error line (each
    // frame does; a script checking errors does it first, so an error that
    // arrived since the frame began is seen).
    void follow_errors();
    [[nodiscard]] const std::string& error_text() const { return error_text_; }
    [[nodiscard]] uint64_t errors_seen() const { return errors_seen_; }
    [[nodiscard]] std::string stats_json();

    static constexpr double kRestSeconds = 0.15;
    // "20261127-101500": local time, for file names.
    static std::string timestamp();  // no camera change for this long ends a motion

private:
    void frame(Clock::time_point now);
    void follow_session(Clock::time_point now);
    void adopt_scene(const std::shared_ptr<const SceneData>& scene);
    void end_motion(Clock::time_point now);
    void finish_screenshots();
    void handle_input(Clock::time_point now);   // viewer_input.cpp
    void draw_panel();                          // viewer_panel.cpp, with the sections below
    void draw_scene_section(const SessionStatus& status);
    void draw_camera_section();
    void draw_bookmarks_section();
    void draw_structure_section(const SessionStatus& status);
    void draw_animation_section(const SessionStatus& status);
    void draw_paged_caches(const PagedStatus& paged);
    void setting_widget(const SettingInfo& info);
    void setting_group(const char* group);
    void draw_overlay(Clock::time_point now);   // viewer_panel.cpp
    void draw_messages(Clock::time_point now);  // viewer_panel.cpp
    [[nodiscard]] double wait_budget(Clock::time_point now) const;
    void apply_settings();
    void save_bookmarks_file();

    const ViewerConfig& config_;
    GlWindow& window_;
    SceneCatalog catalog_;
    std::unique_ptr<Session> session_;
    ViewSettings settings_;
    std::unique_ptr<CameraController> controller_;
    uint64_t scene_id_ = 0;
    std::vector<Bookmark> scene_views_;  // views.json views of the scene shown
    Bookmarks bookmarks_;
    FilmView film_;
    std::shared_ptr<const Frame> shown_;
    ViewerStats stats_;
    std::unique_ptr<ScriptRunner> script_;

    bool moving_ = false;
    bool walking_ = false;   // a walk key is held: tick without events
    Clock::time_point last_move_;
    Clock::time_point last_tick_;
    uint64_t last_camera_version_shown_ = 0;
    std::optional<SceneKind> loading_kind_;  // of the scene last asked for, while jobs are pending

    struct PendingShot {
        std::string path;
        std::future<Image> film;
        ToneMapping tone;
        std::function<void(const std::string&)> done;
    };
    std::vector<PendingShot> shots_;
    std::vector<std::pair<std::string, std::function<void(const std::string&)>>> window_shots_;

    std::string message_;
    bool message_is_error_ = false;
    Clock::time_point message_time_;
    std::string error_text_;   // the newest error shown (load, build, setting)
    uint64_t errors_seen_ = 0;
    uint64_t session_errors_ = 0;
    int screenshot_counter_ = 0;
    bool panel_visible_ = true;
    bool quit_ = false;
    int exit_status_ = 0;

    // Panel state.
    std::string path_input_;
    std::string bookmark_input_;
    std::vector<std::string> devices_;  // cpu, and cuda:N when present
};

}  // namespace rf::viewer
