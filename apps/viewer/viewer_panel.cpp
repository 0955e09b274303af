// The controls panel (scene, camera, bookmarks, structure, integrator,
// image, display, device, screenshots), the statistics overlay and the
// message line. Every setting widget goes through App::set, as a script's
// `set` does.
#include <imgui.h>
#include <imgui_stdlib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <thread>

#include "rayforge/core/error.h"
#include "viewer_app.h"

namespace rf::viewer {
namespace {

constexpr float kPanelWidth = 340.0f;

std::string format(const char* fmt, double value) {
    char text[64];
    std::snprintf(text, sizeof text, fmt, value);
    return text;
}

std::string mib(size_t bytes) { return format("%.1f MiB", double(bytes) / (1024.0 * 1024.0)); }

// "512 B", "3.5 KiB", "1.2 MiB", "2.0 GiB".
std::string bytes_text(double bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    int u = 0;
    for (; bytes >= 1024.0 && u < 4; ++u) bytes /= 1024.0;
    return format(u == 0 ? "%.0f " : "%.1f ", bytes) + units[u];
}

// Whether a setting means anything for the current structure and device.
// A paged scene takes no structure setting, and its path tracer is always
// a wavefront.
bool relevant(const SettingInfo& info, const ViewSettings& s, SceneKind scene) {
    if (!applies_to(info, scene)) return false;
    const std::string& key = info.key;
    if (scene == SceneKind::Paged && key == "wavefront") return false;
    const bool bvh = s.world.build.structure == Structure::Bvh;
    const Builder b = s.world.build.builder;
    if (key == "builder" || key == "layout" || key == "optimize" || key == "leaf-size") return bvh;
    if (key == "optimize-iterations") return bvh && s.world.build.reinsertion.enabled;
    if (key == "bins") return (bvh && b == Builder::BinnedSah) || s.world.build.structure == Structure::KdTree;
    if (key == "sbvh-alpha") return bvh && b == Builder::Sbvh;
    if (key == "ploc-radius") return bvh && (b == Builder::Ploc || b == Builder::Hploc);
    if (key == "split-budget") return bvh && b == Builder::GridBvhSplit;
    if (key == "grid-res") return s.world.build.structure == Structure::Grid || s.world.build.structure == Structure::ProximityGrid;
    if (key == "kd-traversal") return s.world.build.structure == Structure::KdTree;
    if (key == "gpu-kernel") return s.world.device.is_cuda();
    const IntegratorKind i = s.render.integrator;
    if (key == "max-depth" || key == "rr-depth" || key == "light-sampling" || key == "clamp" || key == "wavefront")
        return i == IntegratorKind::Path;
    if (key == "shading" || key == "reflection-depth" || key == "refraction-depth") return i == IntegratorKind::Whitted;
    if (key == "ao-radius" || key == "ao-samples") return i == IntegratorKind::AmbientOcclusion;
    return true;
}

}  // namespace

// A setting's widget: a combo for named values (devices: the ones present),
// a checkbox for on/off, a text field (applied on Enter) for the rest.
void App::setting_widget(const SettingInfo& info) {
    const std::string value = get_setting(settings_, info.key);
    const auto apply = [&](const std::string& v) {
        try {
            set(info.key, v);
        } catch (const Error& e) {
            show_message(e.what(), true);
        }
    };
    const auto combo = [&](const std::vector<std::string>& choices) {
        if (!ImGui::BeginCombo(info.key.c_str(), value.c_str())) return;
        for (const std::string& choice : choices)
            if (ImGui::Selectable(choice.c_str(), choice == value)) apply(choice);
        ImGui::EndCombo();
    };
    ImGui::PushID(info.key.c_str());
    if (info.choices == std::vector<std::string>{"on", "off"}) {
        bool on = value == "on";
        if (ImGui::Checkbox(info.key.c_str(), &on)) apply(on ? "on" : "off");
    } else if (!info.choices.empty()) {
        combo(info.choices);
    } else if (info.key == "device") {
        combo(scene_kind() == SceneKind::Paged ? std::vector<std::string>{"cpu"} : devices_);
    } else {
        std::string edited = value;
        if (ImGui::InputText(info.key.c_str(), &edited, ImGuiInputTextFlags_EnterReturnsTrue)) apply(edited);
    }
    if (ImGui::IsItemHovered()) ImGui::SetTooltip("%s", info.help.c_str());
    ImGui::PopID();
}

void App::setting_group(const char* group) {
    const SceneKind scene = scene_kind();
    for (const SettingInfo& info : setting_infos())
        if (info.group == group && relevant(info, settings_, scene)) setting_widget(info);
}

void App::draw_scene_section(const SessionStatus& status) {
    const bool paged = scene_kind() == SceneKind::Paged;
    ImGui::Text("%s: %zu triangles, %s in %.0f ms", status.scene_name.empty() ? "(loading)" : status.scene_name.c_str(),
                status.triangles, paged ? "paged, opened" : "loaded", status.load_ms);
    if (ImGui::BeginCombo("switch to", "...")) {
        for (const std::string& name : catalog_.shared_names)
            if (ImGui::Selectable(name.c_str())) drop(name);
        if (!catalog_.shared_names.empty()) ImGui::Separator();
        for (const std::string& name : catalog_.builtin_names)
            if (ImGui::Selectable(name.c_str())) drop(name);
        ImGui::EndCombo();
    }
    ImGui::InputText("##path", &path_input_);
    ImGui::SameLine();
    if (ImGui::Button("Open") && !path_input_.empty()) drop(path_input_);
    ImGui::TextDisabled("or drop a scene file onto the window");
}

void App::draw_camera_section() {
    float fov = controller_->camera().vfov_degrees;
    if (ImGui::SliderFloat("fov", &fov, 5.0f, 150.0f, "%.1f deg")) {
        controller_->set_fov(fov);
        camera_placed();
    }
    float speed = controller_->walk_speed();
    if (ImGui::DragFloat("walk speed", &speed, speed * 0.01f + 1e-6f, 0.0f, 0.0f, "%.3g /s"))
        controller_->set_walk_speed(speed);
    if (ImGui::Button("Reset (R)")) reset_camera();
    ImGui::SameLine();
    if (ImGui::Button("Copy --camera (C)")) {
        const std::string text = to_string(controller_->camera());
        ImGui::SetClipboardText(text.c_str());
        std::printf("--camera %s\n", text.c_str());
        std::fflush(stdout);
    }
    std::string text = to_string(controller_->camera());
    ImGui::InputText("--camera", &text, ImGuiInputTextFlags_ReadOnly);
}

void App::draw_bookmarks_section() {
    int index = 1;
    const auto row = [&](const Bookmark& b, bool removable) {
        ImGui::PushID(index);
        if (ImGui::Button(index <= 9 ? std::to_string(index).c_str() : "go")) {
            try {
                load_bookmark(b.name);
            } catch (const Error& e) {
                show_message(e.what(), true);
            }
        }
        ImGui::SameLine();
        ImGui::TextUnformatted(b.name.c_str());
        if (removable) {
            ImGui::SameLine();
            if (ImGui::SmallButton("x")) remove_bookmark(b.name);
        }
        ImGui::PopID();
        ++index;
    };
    for (const Bookmark& b : scene_views_) row(b, false);
    const std::vector<Bookmark> saved = bookmarks_.all();  // a copy: a button may remove one
    for (const Bookmark& b : saved) row(b, true);
    ImGui::InputText("##name", &bookmark_input_);
    ImGui::SameLine();
    if (ImGui::Button("Save (B)"))
        save_bookmark(bookmark_input_.empty() ? "bookmark " + std::to_string(saved.size() + 1) : bookmark_input_);
    ImGui::TextDisabled("file: %s", config_.bookmarks.c_str());
}

void App::draw_structure_section(const SessionStatus& status) {
    if (scene_kind() == SceneKind::Paged)
        ImGui::TextWrapped("%s, from the paged file: the top level and the page BVHs. Structure settings do not "
                           "apply; the page caches' budgets are set at start (--memory-budget).",
                           status.accel.name.c_str());
    setting_group("structure");
    if (!status.busy) return;
    ImGui::ProgressBar(float(status.job_progress), ImVec2(-1, 0), format("%.1f s", status.job_seconds).c_str());
    ImGui::TextWrapped("%s (the current structure renders until it is ready)", status.job.c_str());
}

// Play/pause, the time slider (scrubbing pauses) and the last update.
void App::draw_animation_section(const SessionStatus& status) {
    const AnimationStatus& a = status.animation;
    if (ImGui::Button(a.playing ? "Pause (space)" : "Play (space)")) session_->play(!a.playing);
    float t = a.time;
    if (ImGui::SliderFloat("time", &t, a.start, std::max(a.end, a.start + 1e-3f), "%.3f s")) session_->set_time(t);
    ImGui::Text("frame %d of %d at %.0f fps", int(std::lround((a.time - a.start) * a.frames_per_second)),
                int(std::lround((a.end - a.start) * a.frames_per_second)) + 1, double(a.frames_per_second));
    ImGui::Text("update (%s): %.2f ms, mean %.2f ms", a.method.c_str(), a.last.update_ms, a.mean_update_ms);
    if (a.method == "adapt")
        ImGui::Text("rebuilt subtrees %llu, migrations %llu", (unsigned long long)a.last.rebuilt_subtrees,
                    (unsigned long long)a.last.migrations);
    ImGui::TextDisabled("SAH cost %.2f; the method is the structure's `update` setting", a.last.sah_cost);
}

void App::draw_panel() {
    const ImGuiIO& io = ImGui::GetIO();
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(kPanelWidth, std::max(200.0f, io.DisplaySize.y - 16.0f)), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowBgAlpha(0.85f);
    if (!ImGui::Begin("rayforge (F1 hides)", &panel_visible_)) {
        ImGui::End();
        return;
    }
    ImGui::PushItemWidth(170.0f);  // leaves room for the longest setting names
    const SessionStatus status = session_->status();
    const ImGuiTreeNodeFlags open = ImGuiTreeNodeFlags_DefaultOpen;
    if (ImGui::CollapsingHeader("Scene", open)) draw_scene_section(status);
    if (has_scene() && ImGui::CollapsingHeader("Camera", open)) draw_camera_section();
    if (has_scene() && ImGui::CollapsingHeader("Bookmarks")) draw_bookmarks_section();
    if (status.animation.animated && ImGui::CollapsingHeader("Animation", open)) draw_animation_section(status);
    if (ImGui::CollapsingHeader("Structure", open)) draw_structure_section(status);
    if (ImGui::CollapsingHeader("Integrator", open)) setting_group("integrator");
    if (ImGui::CollapsingHeader("Image")) setting_group("image");
    if (ImGui::CollapsingHeader("Display", open)) setting_group("display");
    if (ImGui::CollapsingHeader("Device")) {
        setting_group("device");
        ImGui::TextDisabled("%u hardware threads; film: %s", std::thread::hardware_concurrency(), film_.path().c_str());
    }
    if (ImGui::Button("Screenshot (F12)")) screenshot_now();
    ImGui::SameLine();
    if (ImGui::Button("Window shot")) screenshot_window("rayforge-window-" + timestamp() + ".png");
    if (!error_text_.empty()) ImGui::TextColored(ImVec4(1, 0.45f, 0.4f, 1), "last error: %s", error_text_.c_str());
    ImGui::PopItemWidth();
    ImGui::End();
}

void App::draw_overlay(Clock::time_point now) {
    const ImGuiIO& io = ImGui::GetIO();
    ImGui::SetNextWindowPos(ImVec2(io.DisplaySize.x - 8, 8), ImGuiCond_Always, ImVec2(1, 0));
    ImGui::SetNextWindowBgAlpha(0.6f);
    const ImGuiWindowFlags flags = ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_AlwaysAutoResize |
                                   ImGuiWindowFlags_NoSavedSettings | ImGuiWindowFlags_NoFocusOnAppearing |
                                   ImGuiWindowFlags_NoNav | ImGuiWindowFlags_NoMove;
    if (!ImGui::Begin("statistics", nullptr, flags)) {
        ImGui::End();
        return;
    }
    const SessionStatus status = session_->status();
    const ViewerStats& s = stats_;
    ImGui::Text("%.1f fps still, %.1f moving (1/%d res)", s.still_frames.per_second(now), s.moving_frames.per_second(now),
                status.motion_divisor);
    ImGui::Text("pass %d / %d  %.1f ms  %.1f Mrays/s", s.passes, s.target_passes, s.ms_per_pass, s.mrays_per_s);
    ImGui::Text("image %dx%d  camera -> image %.0f ms", s.width, s.height, s.camera_latency_ms);
    if (status.paged.caches.empty()) {
        ImGui::Text("%s: build %.1f ms, SAH %.2f", status.accel.name.c_str(), status.accel.build_ms,
                    status.accel.sah_cost);
        ImGui::Text("memory %s (structure %s)", mib(resident_bytes()).c_str(),
                    mib(status.accel.bytes + status.accel.device_bytes).c_str());
    } else {
        ImGui::Text("%s, page caches in the last pass:", status.accel.name.c_str());
        draw_paged_caches(status.paged);
    }
    if (status.animation.animated)
        ImGui::Text("t %.3f s %s  update %.2f ms (%s)", double(status.animation.time),
                    status.animation.playing ? "playing" : "paused", status.animation.last.update_ms,
                    status.animation.method.c_str());
    if (status.busy) ImGui::Text("%s %.0f%%", status.job.c_str(), 100.0 * status.job_progress);
    ImGui::End();
}

// A paged scene's caches: the last pass's hit rate and reads, how full
// each is, and the memory against the budget.
void App::draw_paged_caches(const PagedStatus& paged) {
    for (const PageCacheReport& c : paged.caches) {
        if (c.pages == 0) {
            ImGui::Text("%-10s none in the file", c.name.c_str());
            continue;
        }
        ImGui::Text("%-10s %5.1f%% hit  %s read  %u/%u cached  %s of %s", c.name.c_str(), 100.0 * c.hit_rate(),
                    bytes_text(double(c.bytes_read)).c_str(), c.cached, c.slots,
                    bytes_text(double(c.memory_bytes)).c_str(), bytes_text(double(c.budget_bytes)).c_str());
    }
    ImGui::Text("memory %s (caches %s of %s budget, resident levels %s)", mib(resident_bytes()).c_str(),
                bytes_text(double(paged.cache_bytes)).c_str(), bytes_text(double(paged.budget_bytes)).c_str(),
                bytes_text(double(paged.resident_bytes)).c_str());
}

void App::draw_messages(Clock::time_point now) {
    if (message_.empty() || std::chrono::duration<double>(now - message_time_).count() > 8.0) return;
    const ImGuiIO& io = ImGui::GetIO();
    ImGui::SetNextWindowPos(ImVec2(8, io.DisplaySize.y - 8), ImGuiCond_Always, ImVec2(0, 1));
    ImGui::SetNextWindowBgAlpha(0.75f);
    const ImGuiWindowFlags flags = ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_AlwaysAutoResize |
                                   ImGuiWindowFlags_NoSavedSettings | ImGuiWindowFlags_NoFocusOnAppearing |
                                   ImGuiWindowFlags_NoNav | ImGuiWindowFlags_NoMove;
    if (ImGui::Begin("message", nullptr, flags)) {
        const ImVec4 color = message_is_error_ ? ImVec4(1, 0.45f, 0.4f, 1) : ImVec4(0.8f, 0.9f, 1, 1);
        ImGui::PushTextWrapPos(io.DisplaySize.x - 40);
        ImGui::TextColored(color, "%s%s", message_is_error_ ? "error: " : "", message_.c_str());
        ImGui::PopTextWrapPos();
    }
    ImGui::End();
}

}  // namespace rf::viewer
