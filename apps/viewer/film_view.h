// The film on screen: the latest display image in an OpenGL texture, drawn
// letterboxed behind the panel. A CPU image is uploaded from host memory; a
// CUDA image is copied device to device into a pixel buffer object
// registered with CUDA (rf::GlPixelBuffer) and reaches the texture from
// there, without a trip through host memory. When the OpenGL context cannot
// share memory with the CUDA device (a software OpenGL, another GPU), the
// image is downloaded instead and the panel says why.
#pragma once

#include <memory>
#include <string>

#include "rayforge/render/display.h"

namespace rf::viewer {

class FilmView {
public:
    FilmView();
    ~FilmView();
    FilmView(const FilmView&) = delete;
    FilmView& operator=(const FilmView&) = delete;

    // Puts `image` into the texture.
    void show(const DisplayImage& image);
    // Draws the texture into the window's background, letterboxed to
    // `width` x `height` pixels (the ImGui display size).
    void draw(float width, float height) const;

    [[nodiscard]] bool has_image() const { return width_ > 0; }
    // How the last image reached the texture: "host upload",
    // "CUDA-OpenGL interop (pixel buffer)", or the reason interop was not used.
    [[nodiscard]] const std::string& path() const { return path_; }

private:
    void resize(int width, int height);
    void upload_host(const unsigned char* pixels);
    bool upload_device(const DisplayImage& image);

    unsigned int texture_ = 0;
    unsigned int pixel_buffer_ = 0;
    int width_ = 0, height_ = 0;
    std::unique_ptr<GlPixelBuffer> interop_;
    bool interop_failed_ = false;
    std::string path_;
};

}  // namespace rf::viewer
