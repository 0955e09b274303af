#include "backend/cpu/host_display_image.h"

#include "core/parallel.h"
#include "render/tone_map.h"

namespace rf::cpu {

void HostDisplayImage::assign(std::span<const Vec3f> sums, float scale, int width, int height,
                              const ToneMapping& tone) {
    width_ = width;
    height_ = height;
    pixels_.resize(size_t(width_) * size_t(height_) * 4);
    parallel::for_range(0, height_, 16, [&](int y0, int y1) {
        for (size_t i = size_t(y0) * size_t(width_); i < size_t(y1) * size_t(width_); ++i) {
            tone_map_pixel(sums[i] * scale, tone, &pixels_[4 * i]);  // the mean as image() has it
            pixels_[4 * i + 3] = 255;
        }
    });
}

}  // namespace rf::cpu
