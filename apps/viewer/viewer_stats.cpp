#include "viewer_stats.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include <nlohmann/json.hpp>

namespace rf::viewer {

size_t resident_bytes() {
    std::ifstream statm("/proc/self/statm");
    size_t total_pages = 0, resident_pages = 0;
    if (!(statm >> total_pages >> resident_pages)) return 0;
    return resident_pages * size_t(sysconf(_SC_PAGESIZE));
}

namespace {

// A paged scene's caches: per cache the last pass's counts and the cache's
// state, and the memory against the budget.
nlohmann::json paged_json(const PagedStatus& p) {
    nlohmann::json caches = nlohmann::json::object();
    for (const PageCacheReport& c : p.caches)
        caches[c.name] = {{"hit_rate", c.hit_rate()},   {"requests", c.requests},     {"bytes_read", c.bytes_read},
                          {"pages_read", c.pages_read}, {"evictions", c.evictions},   {"cached", c.cached},
                          {"slots", c.slots},           {"pages", c.pages},           {"memory_bytes", c.memory_bytes},
                          {"budget_bytes", c.budget_bytes}};
    return {{"memory_bytes", p.cache_bytes},
            {"budget_bytes", p.budget_bytes},
            {"resident_bytes", p.resident_bytes},
            {"caches", caches}};
}

}  // namespace

void RateMeter::add(Clock::time_point t) {
    times_.push_back(t);
    while (!times_.empty() && std::chrono::duration<double>(t - times_.front()).count() > window_s_) times_.pop_front();
}

double RateMeter::per_second(Clock::time_point now) const {
    // Frames that stopped coming are no rate: nothing in the last window is 0.
    if (times_.size() < 2 || std::chrono::duration<double>(now - times_.back()).count() > window_s_) return 0.0;
    const double span = std::chrono::duration<double>(times_.back() - times_.front()).count();
    return span > 0.0 ? double(times_.size() - 1) / span : 0.0;
}

void ViewerStats::frame_shown(const Frame& frame, Clock::time_point now, bool first_of_camera) {
    (frame.preview ? moving_frames : still_frames).add(now);
    passes = frame.passes;
    target_passes = frame.target_passes;
    ms_per_pass = frame.pass_ms;
    mrays_per_s = frame.pass_ms > 0.0 ? double(frame.pass_rays) / (frame.pass_ms * 1e3) : 0.0;
    width = frame.image ? frame.image->width() : 0;
    height = frame.image ? frame.image->height() : 0;
    ++frames_shown;
    if (first_of_camera) {
        camera_latency_ms = std::chrono::duration<double, std::milli>(now - frame.camera_time).count();
        max_camera_latency_ms = std::max(max_camera_latency_ms, camera_latency_ms);
    }
}

std::string ViewerStats::json(const SessionStatus& status, Clock::time_point now) const {
    const auto finite = [](double v) { return std::isfinite(v) ? v : -1.0; };
    nlohmann::json j = {
        {"scene", status.scene_name},
        {"triangles", status.triangles},
        {"structure", status.accel.name},
        {"build_ms", finite(status.accel.build_ms)},
        {"sah_cost", finite(status.accel.sah_cost)},
        {"structure_bytes", status.accel.bytes + status.accel.device_bytes},
        {"width", width},
        {"height", height},
        {"passes", passes},
        {"target_passes", target_passes},
        {"ms_per_pass", ms_per_pass},
        {"mrays_per_s", mrays_per_s},
        {"still_fps", still_frames.per_second(now)},
        {"moving_fps", moving_frames.per_second(now)},
        {"ui_fps", ui_frames.per_second(now)},
        {"motion_divisor", status.motion_divisor},
        {"camera_latency_ms", camera_latency_ms},
        {"max_camera_latency_ms", max_camera_latency_ms},
        {"max_ui_frame_ms", max_ui_frame_ms},
        {"ui_frame_ms", ui_frame_ms},
        {"first_image_ms", first_image_ms},
        {"frames_shown", frames_shown},
        {"resident_mib", double(resident_bytes()) / (1024.0 * 1024.0)},
        {"errors", status.error_count},
    };
    if (!status.paged.caches.empty()) j["paged"] = paged_json(status.paged);
    if (status.animation.animated) {
        const AnimationStatus& a = status.animation;
        j["animation"] = {{"time", a.time},          {"playing", a.playing},
                          {"method", a.method},      {"updates", a.updates},
                          {"update_ms", a.last.update_ms}, {"mean_update_ms", a.mean_update_ms},
                          {"rebuilt_subtrees", a.last.rebuilt_subtrees}, {"migrations", a.last.migrations}};
    }
    return j.dump();
}

}  // namespace rf::viewer
