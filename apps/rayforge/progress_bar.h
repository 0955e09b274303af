// Progress on stderr for long operations. Nothing is shown for work that
// finishes within the first second. On a terminal the bar is redrawn in
// place with a percentage and an ETA; otherwise (logs, CI) plain lines like
// "render: 25%" are printed at quarter steps.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace rf::cli {

class ProgressBar {
public:
    explicit ProgressBar(std::string label, std::FILE* stream = stderr);
    ~ProgressBar();
    ProgressBar(const ProgressBar&) = delete;
    ProgressBar& operator=(const ProgressBar&) = delete;

    // fraction in [0, 1]; call from one thread at a time.
    void update(double fraction);
    // Ends the bar's line (terminal) once the work is done.
    void finish();
    // Text shown after the percentage from the next update on (e.g. cache statistics).
    void set_note(std::string note) { note_ = std::move(note); }

private:
    using Clock = std::chrono::steady_clock;
    void draw(double fraction, double elapsed_s);

    std::string label_;
    std::string note_;
    std::FILE* stream_;
    bool is_tty_;
    Clock::time_point start_;
    Clock::time_point last_draw_;
    bool shown_ = false;
    bool finished_ = false;
    int last_step_ = 0;  // non-terminal: quarters already printed
};

}  // namespace rf::cli
