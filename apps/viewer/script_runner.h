// Runs a parsed script against the viewer, a few commands per window frame:
// actions happen at once, waits are checked each frame against the
// session's frames and status, and every wait gives up after the timeout.
// The first failure ends the script with "FILE:LINE: why" on stderr.
#pragma once

#include <memory>
#include <string>

#include "script.h"
#include "session.h"

namespace rf::viewer {

class App;

class ScriptRunner {
public:
    ScriptRunner(Script script, double timeout_s);
    // Runs commands until one waits or the script ends.
    void step(App& app, Clock::time_point now);
    [[nodiscard]] bool finished() const { return finished_; }
    [[nodiscard]] bool failed() const { return !failure_.empty(); }
    [[nodiscard]] const std::string& failure() const { return failure_; }
    // The current command moves the camera every frame (walk).
    [[nodiscard]] bool wants_ticks() const;
    // Seconds until the current command's sleep ends or its wait times out.
    [[nodiscard]] double seconds_to_deadline(Clock::time_point now) const;

private:
    // Starts the current command; true when it is already done.
    bool start(App& app, const ScriptCommand& c, Clock::time_point now);
    // Whether the started command is done (throws rf::Error when it failed).
    bool poll(App& app, const ScriptCommand& c, Clock::time_point now);
    void fail(const ScriptCommand& c, const std::string& why);

    Script script_;
    double timeout_s_;
    size_t next_ = 0;
    bool running_ = false;       // the current command started and waits
    bool finished_ = false;
    std::string failure_;
    // The waiting command's state.
    Clock::time_point started_at_, last_step_;
    uint64_t frames_at_start_ = 0;
    uint64_t errors_at_start_ = 0;
    uint64_t errors_acknowledged_ = 0;  // errors expected by expect-error so far
    double walked_s_ = 0.0;
    std::shared_ptr<bool> done_;        // set by a screenshot's completion
    std::shared_ptr<std::string> done_error_;
};

}  // namespace rf::viewer
