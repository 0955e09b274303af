#include "film_view.h"

#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GL/glext.h>
#include <GLFW/glfw3.h>
#include <imgui.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "rayforge/core/error.h"

namespace rf::viewer {
namespace {

// The buffer-object entry points (OpenGL 1.5) are not exported by every
// libGL; they come from the context.
struct BufferApi {
    PFNGLGENBUFFERSPROC gen = nullptr;
    PFNGLDELETEBUFFERSPROC remove = nullptr;
    PFNGLBINDBUFFERPROC bind = nullptr;
    PFNGLBUFFERDATAPROC data = nullptr;

    static const BufferApi& get() {
        static const BufferApi api = [] {
            BufferApi a;
            a.gen = reinterpret_cast<PFNGLGENBUFFERSPROC>(glfwGetProcAddress("glGenBuffers"));
            a.remove = reinterpret_cast<PFNGLDELETEBUFFERSPROC>(glfwGetProcAddress("glDeleteBuffers"));
            a.bind = reinterpret_cast<PFNGLBINDBUFFERPROC>(glfwGetProcAddress("glBindBuffer"));
            a.data = reinterpret_cast<PFNGLBUFFERDATAPROC>(glfwGetProcAddress("glBufferData"));
            return a;
        }();
        return api;
    }
    [[nodiscard]] bool complete() const { return gen && remove && bind && data; }
};

}  // namespace

FilmView::FilmView() {
    glGenTextures(1, &texture_);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
}

FilmView::~FilmView() {
    interop_.reset();  // unregistered before the buffer goes
    if (pixel_buffer_) BufferApi::get().remove(1, &pixel_buffer_);
    glDeleteTextures(1, &texture_);
}

void FilmView::resize(int width, int height) {
    if (width == width_ && height == height_) return;
    width_ = width;
    height_ = height;
    glBindTexture(GL_TEXTURE_2D, texture_);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, width, height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    interop_.reset();  // the pixel buffer is sized for the image
}

void FilmView::upload_host(const unsigned char* pixels) {
    glBindTexture(GL_TEXTURE_2D, texture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
}

bool FilmView::upload_device(const DisplayImage& image) {
    const BufferApi& gl = BufferApi::get();
    if (interop_failed_) return false;
    if (!gl.complete()) {
        interop_failed_ = true;
        path_ = "host copy (no OpenGL buffer objects)";
        return false;
    }
    try {
        if (!interop_) {
            if (!pixel_buffer_) gl.gen(1, &pixel_buffer_);
            gl.bind(GL_PIXEL_UNPACK_BUFFER, pixel_buffer_);
            gl.data(GL_PIXEL_UNPACK_BUFFER, GLsizeiptr(size_t(width_) * size_t(height_) * 4), nullptr, GL_STREAM_DRAW);
            gl.bind(GL_PIXEL_UNPACK_BUFFER, 0);
            interop_ = register_gl_pixel_buffer(image.device(), pixel_buffer_);
        }
        interop_->copy_from(image);
    } catch (const Error& e) {
        interop_failed_ = true;
        interop_.reset();
        path_ = std::string("host copy (") + e.what() + ")";
        return false;
    }
    gl.bind(GL_PIXEL_UNPACK_BUFFER, pixel_buffer_);
    glBindTexture(GL_TEXTURE_2D, texture_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    gl.bind(GL_PIXEL_UNPACK_BUFFER, 0);
    path_ = "CUDA-OpenGL interop (pixel buffer)";
    return true;
}

void FilmView::show(const DisplayImage& image) {
    if (image.width() <= 0 || image.height() <= 0) return;
    resize(image.width(), image.height());
    if (const unsigned char* pixels = image.host_pixels()) {
        upload_host(pixels);
        path_ = "host upload";
        return;
    }
    if (upload_device(image)) return;
    const std::vector<uint8_t> pixels = image.download();
    upload_host(pixels.data());
}

void FilmView::draw(float width, float height) const {
    if (!has_image() || width <= 0 || height <= 0) return;
    const float scale = std::min(width / float(width_), height / float(height_));
    const float w = float(width_) * scale, h = float(height_) * scale;
    const ImVec2 p0((width - w) * 0.5f, (height - h) * 0.5f);
    ImGui::GetBackgroundDrawList()->AddImage(reinterpret_cast<ImTextureID>(uintptr_t(texture_)), p0,
                                             ImVec2(p0.x + w, p0.y + h));
}

}  // namespace rf::viewer
