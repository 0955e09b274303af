// What the statistics overlay shows and `print-stats` prints: frame rates
// (still, at full resolution, and moving, in previews), pass times and ray
// rates, the structure's build time and SAH cost (a paged scene: its page
// caches), memory, the delay from a camera change to its first image, and
// the longest the window went without drawing (a blocked window).
#pragma once

#include <algorithm>
#include <cstddef>
#include <deque>
#include <string>

#include "session.h"

namespace rf::viewer {

// The resident set of this process (/proc/self/statm), 0 when unknown.
size_t resident_bytes();

// Frames per second over the last `window_s` seconds of frame times.
class RateMeter {
public:
    explicit RateMeter(double window_s = 2.0) : window_s_(window_s) {}
    void add(Clock::time_point t);
    [[nodiscard]] double per_second(Clock::time_point now) const;
    void clear() { times_.clear(); }

private:
    double window_s_;
    std::deque<Clock::time_point> times_;
};

struct ViewerStats {
    RateMeter still_frames, moving_frames, ui_frames;
    int passes = 0, target_passes = 0;
    double ms_per_pass = 0.0;
    double mrays_per_s = 0.0;
    int width = 0, height = 0;       // of the image shown
    double camera_latency_ms = 0.0;  // the last camera change to its first image
    double max_camera_latency_ms = 0.0;
    double max_ui_frame_ms = 0.0;    // since the last reset
    double ui_frame_ms = 0.0;        // the window's work per frame, averaged over about 30 frames
    double first_image_ms = -1.0;    // launch to the first image
    uint64_t frames_shown = 0;

    // A new frame reached the screen at `now`.
    void frame_shown(const Frame& frame, Clock::time_point now, bool first_of_camera);
    void ui_frame_done(double ms) {
        max_ui_frame_ms = std::max(max_ui_frame_ms, ms);
        ui_frame_ms += (ms - ui_frame_ms) / 30.0;
    }
    // The maxima and the rates start afresh (script: reset-stats).
    void reset() {
        max_camera_latency_ms = 0.0;
        max_ui_frame_ms = 0.0;
        still_frames.clear();
        moving_frames.clear();
        ui_frames.clear();
    }
    // One JSON object on one line, with the session's status.
    [[nodiscard]] std::string json(const SessionStatus& status, Clock::time_point now) const;
};

}  // namespace rf::viewer
