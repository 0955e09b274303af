#include "script_runner.h"

#include <cstdio>

#include "rayforge/core/error.h"
#include "viewer_app.h"

namespace rf::viewer {
namespace {

double seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

}  // namespace

ScriptRunner::ScriptRunner(Script script, double timeout_s) : script_(std::move(script)), timeout_s_(timeout_s) {}

bool ScriptRunner::wants_ticks() const {
    return running_ && next_ < script_.commands.size() && script_.commands[next_].op == ScriptOp::Walk;
}

double ScriptRunner::seconds_to_deadline(Clock::time_point now) const {
    if (!running_ || next_ >= script_.commands.size()) return 0.0;  // the next command starts at once
    const ScriptCommand& c = script_.commands[next_];
    const double waited = seconds(started_at_, now);
    return (c.op == ScriptOp::Sleep ? std::min(c.a, timeout_s_) : timeout_s_) - waited;
}

void ScriptRunner::fail(const ScriptCommand& c, const std::string& why) {
    failure_ = script_.where(c) + ": " + c.text + ": " + why;
    std::fprintf(stderr, "rayforge: error: %s\n", failure_.c_str());
    finished_ = true;
}

void ScriptRunner::step(App& app, Clock::time_point now) {
    // A few commands per frame, so a long list of actions does not stall drawing.
    for (int budget = 64; budget > 0 && !finished_; --budget) {
        if (next_ >= script_.commands.size()) {
            finished_ = true;
            return;
        }
        const ScriptCommand& c = script_.commands[next_];
        try {
            if (!running_) {
                started_at_ = last_step_ = now;
                frames_at_start_ = app.stats().frames_shown;
                errors_at_start_ = app.errors_seen();
                walked_s_ = 0.0;
                if (!start(app, c, now)) {
                    running_ = true;
                    return;
                }
            } else if (!poll(app, c, now)) {
                if (seconds(started_at_, now) > timeout_s_)
                    throw Error("timed out after " + std::to_string(int(timeout_s_)) + " s");
                return;
            }
        } catch (const std::exception& e) {
            fail(c, e.what());
            return;
        }
        running_ = false;
        ++next_;
    }
}

bool ScriptRunner::start(App& app, const ScriptCommand& c, Clock::time_point now) {
    const auto need_scene = [&] {
        if (!app.has_scene()) throw Error("no scene is shown yet (wait-idle or wait-passes first)");
    };
    const auto moved = [&](bool accepted) {
        if (!accepted) throw Error("the camera would not render after this motion (it overflows); unchanged");
        app.camera_moved();
    };
    switch (c.op) {
        case ScriptOp::WaitPasses:
        case ScriptOp::WaitFrames:
        case ScriptOp::WaitIdle:
        case ScriptOp::Sleep:
        case ScriptOp::ExpectError:
        case ScriptOp::ExpectNoError: return poll(app, c, now);
        case ScriptOp::Orbit: need_scene(); moved(app.controller().orbit(float(c.a), float(c.b))); return true;
        case ScriptOp::Look: need_scene(); moved(app.controller().look(float(c.a), float(c.b))); return true;
        case ScriptOp::Pan:
            need_scene();
            moved(app.controller().pan(float(c.a), float(c.b), app.settings().render.height));
            return true;
        case ScriptOp::Dolly: need_scene(); moved(app.controller().dolly(float(c.a))); return true;
        case ScriptOp::Walk: need_scene(); return poll(app, c, now);
        case ScriptOp::Fov:
            need_scene();
            if (!app.controller().set_fov(float(c.a))) throw Error("the camera would not render");
            app.camera_placed();
            return true;
        case ScriptOp::Camera: need_scene(); app.controller().set(parse_camera(c.rest)); app.camera_placed(); return true;
        case ScriptOp::Reset: need_scene(); app.reset_camera(); return true;
        case ScriptOp::BookmarkSave: app.save_bookmark(c.rest); return true;
        case ScriptOp::BookmarkLoad: app.load_bookmark(c.rest); return true;
        case ScriptOp::Set: app.set(c.word, c.rest); return true;
        case ScriptOp::Load: app.load(c.rest); return true;
        case ScriptOp::Drop: app.drop(c.rest); return true;
        case ScriptOp::Screenshot:
        case ScriptOp::ScreenshotWindow: {
            done_ = std::make_shared<bool>(false);
            done_error_ = std::make_shared<std::string>();
            auto finished = [done = done_, error = done_error_](const std::string& why) {
                *error = why;
                *done = true;
            };
            if (c.op == ScriptOp::Screenshot) app.screenshot(c.rest, finished);
            else app.screenshot_window(c.rest, finished);
            return false;
        }
        case ScriptOp::PrintCamera:
            need_scene();
            std::printf("%s\n", to_string(app.controller().camera()).c_str());
            std::fflush(stdout);
            return true;
        case ScriptOp::PrintStats:
            std::printf("%s\n", app.stats_json().c_str());
            std::fflush(stdout);
            return true;
        case ScriptOp::ResetStats: app.stats().reset(); return true;
        case ScriptOp::Play: need_scene(); app.session().play(true); return true;
        case ScriptOp::Pause: need_scene(); app.session().play(false); return true;
        case ScriptOp::Time: need_scene(); app.session().set_time(float(c.a)); return true;
        case ScriptOp::Quit: app.quit(0); finished_ = true; return true;
    }
    return true;
}

bool ScriptRunner::poll(App& app, const ScriptCommand& c, Clock::time_point now) {
    const Versions versions = app.session().versions();
    app.follow_errors();  // after reading the versions: an error of a finished job is in by now
    // An error while waiting for the renderer fails the wait (expect-error waits for it instead).
    const bool new_error = app.errors_seen() > errors_at_start_;
    const auto fail_on_error = [&] {
        if (new_error) throw Error("the viewer reported an error: " + app.error_text());
    };
    switch (c.op) {
        case ScriptOp::WaitPasses: {
            fail_on_error();
            const std::shared_ptr<const Frame> frame = app.shown_frame();
            if (app.settings().render.spp < int(c.a))
                throw Error("the image stops at " + std::to_string(app.settings().render.spp) +
                            " passes (set spp to more)");
            return frame && app.scene_adopted() && !app.moving() && versions.shown_by(*frame) && !frame->preview &&
                   frame->passes >= int(c.a);
        }
        case ScriptOp::WaitFrames: fail_on_error(); return app.stats().frames_shown >= frames_at_start_ + uint64_t(c.a);
        case ScriptOp::WaitIdle: fail_on_error(); return !versions.jobs_pending && app.scene_adopted();
        case ScriptOp::Sleep: return seconds(started_at_, now) >= c.a;
        case ScriptOp::ExpectError: {
            if (versions.jobs_pending) return false;
            if (app.errors_seen() == errors_acknowledged_ || app.error_text().find(c.rest) == std::string::npos)
                throw Error("expected an error containing '" + c.rest + "', the window shows '" +
                            (app.errors_seen() == errors_acknowledged_ ? std::string("no error") : app.error_text()) +
                            "'");
            errors_acknowledged_ = app.errors_seen();
            return true;
        }
        case ScriptOp::ExpectNoError:
            if (versions.jobs_pending) return false;
            if (app.errors_seen() != errors_acknowledged_) throw Error("the window shows an error: " + app.error_text());
            return true;
        case ScriptOp::Walk: {
            const double step = std::min(seconds(last_step_, now), c.a - walked_s_);
            last_step_ = now;
            if (step > 0.0) {
                if (!app.controller().walk(parse_walk_direction(c.word), float(step), c.fast))
                    throw Error("the camera would not render after this walk (it overflows)");
                walked_s_ += step;
            }
            app.camera_moved();
            return walked_s_ >= c.a;
        }
        case ScriptOp::Screenshot:
        case ScriptOp::ScreenshotWindow:
            if (!*done_) return false;
            if (!done_error_->empty()) throw Error(*done_error_);
            return true;
        default: return true;
    }
}

}  // namespace rf::viewer
