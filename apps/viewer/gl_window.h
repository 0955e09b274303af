// The viewer's window: GLFW 3.3 with an OpenGL 3.3 core context and Dear
// ImGui (its GLFW and OpenGL 3 backends from Debian's libimgui-dev), made
// and torn down together. Files dropped onto the window are queued for the
// viewer to read.
#pragma once

#include <string>
#include <vector>

struct GLFWwindow;

namespace rf::viewer {

class GlWindow {
public:
    // Throws rf::Error with GLFW's reason when no window can be opened (no
    // display, no OpenGL 3.3).
    GlWindow(int width, int height, const std::string& title);
    ~GlWindow();
    GlWindow(const GlWindow&) = delete;
    GlWindow& operator=(const GlWindow&) = delete;

    [[nodiscard]] GLFWwindow* handle() const { return window_; }
    [[nodiscard]] bool should_close() const;
    void set_title(const std::string& title);
    // Framebuffer size in pixels.
    void framebuffer_size(int& width, int& height) const;

    // Waits for input (or a wake-up) at most `timeout_s` seconds; 0 polls.
    void wait_events(double timeout_s);
    // Makes a waiting wait_events return; callable from any thread.
    static void wake();

    void begin_frame();  // ImGui's new frame
    void end_frame();    // ImGui drawn into the back buffer (swap() shows it)
    void swap();

    // Paths dropped onto the window since the last call.
    std::vector<std::string> take_dropped();
    // The back buffer as RGBA rows, top row first (after end_frame, before swap).
    [[nodiscard]] std::vector<unsigned char> read_back(int& width, int& height) const;

    // The GL version string of the context (e.g. "3.3 (Core Profile) Mesa 22.3.6").
    [[nodiscard]] std::string gl_version() const;

private:
    GLFWwindow* window_ = nullptr;
    std::vector<std::string> dropped_;
};

}  // namespace rf::viewer
