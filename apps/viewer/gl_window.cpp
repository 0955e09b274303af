#include "gl_window.h"

#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <algorithm>
#include <mutex>
#include <utility>

#include "rayforge/core/error.h"

namespace rf::viewer {
namespace {

// GLFW reports errors through a callback; the last one explains a failure.
std::mutex error_mutex;
std::string last_glfw_error;

void on_glfw_error(int code, const char* description) {
    std::lock_guard<std::mutex> lock(error_mutex);
    last_glfw_error = std::string(description ? description : "unknown") + " (GLFW error " + std::to_string(code) + ")";
}

std::string glfw_error() {
    std::lock_guard<std::mutex> lock(error_mutex);
    return last_glfw_error.empty() ? "no reason given" : last_glfw_error;
}

void on_drop(GLFWwindow* window, int count, const char** paths) {
    auto* self = static_cast<std::vector<std::string>*>(glfwGetWindowUserPointer(window));
    for (int i = 0; i < count; ++i) self->emplace_back(paths[i]);
}

}  // namespace

GlWindow::GlWindow(int width, int height, const std::string& title) {
    glfwSetErrorCallback(on_glfw_error);
    if (!glfwInit()) throw Error("cannot open a window: " + glfw_error() + "; is there a display (DISPLAY, xvfb-run)?");
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    window_ = glfwCreateWindow(std::max(width, 64), std::max(height, 64), title.c_str(), nullptr, nullptr);
    if (!window_) {
        const std::string why = glfw_error();
        glfwTerminate();
        throw Error("cannot open an OpenGL 3.3 window: " + why);
    }
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(1);  // at most the display's rate: the renderer needs the cores more
    glfwSetWindowUserPointer(window_, &dropped_);
    glfwSetDropCallback(window_, on_drop);  // before ImGui, which chains to it

    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini next to the user's files
    ImGui::StyleColorsDark();
    ImGui_ImplGlfw_InitForOpenGL(window_, true);
    ImGui_ImplOpenGL3_Init("#version 330 core");
}

GlWindow::~GlWindow() {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window_);
    glfwTerminate();
}

bool GlWindow::should_close() const { return glfwWindowShouldClose(window_) != 0; }

void GlWindow::set_title(const std::string& title) { glfwSetWindowTitle(window_, title.c_str()); }

void GlWindow::framebuffer_size(int& width, int& height) const { glfwGetFramebufferSize(window_, &width, &height); }

void GlWindow::wait_events(double timeout_s) {
    if (timeout_s <= 0.0) glfwPollEvents();
    else glfwWaitEventsTimeout(timeout_s);
}

void GlWindow::wake() { glfwPostEmptyEvent(); }

void GlWindow::begin_frame() {
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
}

void GlWindow::end_frame() {
    ImGui::Render();
    int width = 0, height = 0;
    framebuffer_size(width, height);
    glViewport(0, 0, width, height);
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
}

void GlWindow::swap() { glfwSwapBuffers(window_); }

std::vector<std::string> GlWindow::take_dropped() { return std::exchange(dropped_, {}); }

std::vector<unsigned char> GlWindow::read_back(int& width, int& height) const {
    framebuffer_size(width, height);
    std::vector<unsigned char> rows(size_t(width) * size_t(height) * 4);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadBuffer(GL_BACK);
    glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
    // OpenGL's rows start at the bottom.
    const size_t stride = size_t(width) * 4;
    for (int y = 0; y < height / 2; ++y)
        std::swap_ranges(rows.begin() + long(size_t(y) * stride), rows.begin() + long(size_t(y + 1) * stride),
                         rows.begin() + long(size_t(height - 1 - y) * stride));
    return rows;
}

std::string GlWindow::gl_version() const {
    const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
    return version ? version : "unknown";
}

}  // namespace rf::viewer
