// A float RGB image (linear radiance), row 0 at the top.
#pragma once

#include <vector>

#include "rayforge/math/vec.h"

namespace rf {

struct Image {
    int width = 0;
    int height = 0;
    std::vector<Vec3f> pixels;

    Image() = default;
    Image(int w, int h) : width(w), height(h), pixels(size_t(w) * size_t(h)) {}
    [[nodiscard]] Vec3f& at(int x, int y) { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
    [[nodiscard]] const Vec3f& at(int x, int y) const { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
};

}  // namespace rf
