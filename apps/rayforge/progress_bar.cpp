#include "progress_bar.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace rf::cli {

namespace {
constexpr double kQuietSeconds = 1.0;       // work shorter than this shows nothing
constexpr double kRedrawSeconds = 0.1;      // terminal redraw rate limit
constexpr int kBarWidth = 30;
}  // namespace

ProgressBar::ProgressBar(std::string label, std::FILE* stream)
    : label_(std::move(label)), stream_(stream), is_tty_(isatty(fileno(stream)) != 0),
      start_(Clock::now()), last_draw_(start_) {}

ProgressBar::~ProgressBar() { finish(); }

void ProgressBar::update(double fraction) {
    if (finished_) return;
    fraction = std::clamp(fraction, 0.0, 1.0);
    Clock::time_point now = Clock::now();
    double elapsed = std::chrono::duration<double>(now - start_).count();
    if (elapsed < kQuietSeconds) return;
    if (is_tty_) {
        if (shown_ && fraction < 1.0 && std::chrono::duration<double>(now - last_draw_).count() < kRedrawSeconds)
            return;
        last_draw_ = now;
        draw(fraction, elapsed);
    } else {
        int step = int(std::floor(fraction * 4.0));
        if (step <= last_step_) return;
        last_step_ = step;
        std::fprintf(stream_, "%s: %d%%%s%s\n", label_.c_str(), step * 25, note_.empty() ? "" : " ", note_.c_str());
        std::fflush(stream_);
        shown_ = true;
    }
}

void ProgressBar::draw(double fraction, double elapsed_s) {
    int filled = int(fraction * kBarWidth);
    std::string bar(size_t(filled), '#');
    bar.append(size_t(kBarWidth - filled), '-');
    std::string eta = "--";
    if (fraction > 0.0) {
        int remaining = int(std::lround(elapsed_s * (1.0 - fraction) / fraction));
        eta = remaining >= 60 ? std::to_string(remaining / 60) + "m" + std::to_string(remaining % 60) + "s"
                              : std::to_string(remaining) + "s";
    }
    std::fprintf(stream_, "\r%s [%s] %3d%% ETA %-8s%s\033[K", label_.c_str(), bar.c_str(), int(fraction * 100.0),
                 eta.c_str(), note_.c_str());
    std::fflush(stream_);
    shown_ = true;
}

void ProgressBar::finish() {
    if (finished_) return;
    finished_ = true;
    if (shown_ && is_tty_) {
        std::fputc('\n', stream_);
        std::fflush(stream_);
    }
}

}  // namespace rf::cli
