// Mouse and keyboard: left drag orbits, right drag turns the view, middle
// drag (or shift + left drag) pans, the wheel dollies; W A S D walk, E and
// Q rise and sink, shift walks four times faster; R resets the camera, 1-9
// go to bookmarks, B saves one, [ and ] change the field of view, C prints
// the camera, F1 hides the panel, F12 takes a screenshot, Esc quits. Input
// an ImGui widget takes is not the camera's.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>

#include <algorithm>
#include <cstdio>

#include "rayforge/core/error.h"
#include "viewer_app.h"

namespace rf::viewer {
namespace {

constexpr float kOrbitDegreesPerPixel = 0.3f;
constexpr float kLookDegreesPerPixel = 0.15f;

struct WalkKey {
    int key;
    WalkDirection direction;
};
constexpr WalkKey kWalkKeys[] = {
    {GLFW_KEY_W, WalkDirection::Forward}, {GLFW_KEY_S, WalkDirection::Back}, {GLFW_KEY_A, WalkDirection::Left},
    {GLFW_KEY_D, WalkDirection::Right},   {GLFW_KEY_E, WalkDirection::Up},   {GLFW_KEY_Q, WalkDirection::Down},
};

bool pressed(int key) { return ImGui::IsKeyPressed(key, false); }

}  // namespace

void App::handle_input(Clock::time_point now) {
    ImGuiIO& io = ImGui::GetIO();
    const bool shift = io.KeyShift;
    bool moved = false;
    if (!io.WantCaptureMouse) {
        const ImVec2 d = io.MouseDelta;
        const bool left = ImGui::IsMouseDown(ImGuiMouseButton_Left), middle = ImGui::IsMouseDown(ImGuiMouseButton_Middle);
        const bool right = ImGui::IsMouseDown(ImGuiMouseButton_Right);
        if (d.x != 0.0f || d.y != 0.0f) {
            if (middle || (left && shift)) controller_->pan(d.x, d.y, std::max(1, int(io.DisplaySize.y)));
            else if (left) controller_->orbit(-d.x * kOrbitDegreesPerPixel, d.y * kOrbitDegreesPerPixel);
            else if (right) controller_->look(d.x * kLookDegreesPerPixel, -d.y * kLookDegreesPerPixel);
            moved = left || middle || right;
        }
        if (io.MouseWheel != 0.0f) {
            controller_->dolly(io.MouseWheel);
            moved = true;
        }
    }
    walking_ = false;
    if (!io.WantCaptureKeyboard) {
        const float dt = std::clamp(io.DeltaTime, 0.0f, 0.1f);
        for (const WalkKey& k : kWalkKeys)
            if (glfwGetKey(window_.handle(), k.key) == GLFW_PRESS) {
                controller_->walk(k.direction, dt, shift);
                walking_ = moved = true;
            }
        if (pressed(GLFW_KEY_R)) reset_camera();
        if (pressed(GLFW_KEY_LEFT_BRACKET) || pressed(GLFW_KEY_RIGHT_BRACKET)) {
            controller_->set_fov(controller_->camera().vfov_degrees * (pressed(GLFW_KEY_LEFT_BRACKET) ? 0.9f : 1.1f));
            camera_placed();
        }
        if (pressed(GLFW_KEY_C)) {
            const std::string text = to_string(controller_->camera());
            std::printf("--camera %s\n", text.c_str());
            std::fflush(stdout);
            ImGui::SetClipboardText(text.c_str());
            show_message("camera copied: --camera " + text, false);
        }
        if (pressed(GLFW_KEY_B)) {
            save_bookmark("bookmark " + std::to_string(bookmarks_.all().size() + 1));
        }
        for (int digit = 1; digit <= 9; ++digit) {
            if (!pressed(GLFW_KEY_0 + digit)) continue;
            std::vector<std::string> names;
            for (const Bookmark& b : scene_views_) names.push_back(b.name);
            for (const Bookmark& b : bookmarks_.all()) names.push_back(b.name);
            if (size_t(digit) > names.size()) continue;
            try {
                load_bookmark(names[size_t(digit - 1)]);
            } catch (const Error& e) {
                show_message(e.what(), true);
            }
        }
        if (pressed(GLFW_KEY_SPACE)) session_->play(!session_->status().animation.playing);
        if (pressed(GLFW_KEY_F1)) panel_visible_ = !panel_visible_;
        if (pressed(GLFW_KEY_F12)) screenshot_now();
        if (pressed(GLFW_KEY_ESCAPE)) quit(0);
    }
    if (moved) camera_moved();
    (void)now;
}

}  // namespace rf::viewer
