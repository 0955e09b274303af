// What the CPU's renderers share beyond RendererBase: films of per-pixel
// sums in host vectors and the host display image (the in-core renderer,
// backend/cpu/cpu_renderer.cpp, and the paged scenes', ooc/paged_renderer.cpp).
#pragma once

#include <memory>
#include <vector>

#include "backend/cpu/host_display_image.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "render/pixel_sample.h"
#include "render/renderer_base.h"

namespace rf::cpu {

class HostFilmRenderer : public RendererBase {
public:
    [[nodiscard]] std::unique_ptr<DisplayImage> make_display_image() const override {
        return std::make_unique<HostDisplayImage>();
    }

    void update_display(DisplayImage& display, const ToneMapping& tone) const override {
        auto* host = dynamic_cast<HostDisplayImage*>(&display);
        if (!host) throw Error("update_display: the display image is not a CPU one (make it with this renderer)");
        const float scale = passes() > 0 ? 1.0f / float(passes()) : 0.0f;  // image()'s scale
        parallel::with_threads(options().threads,
                               [&] { host->assign(color_, scale, options().width, options().height, tone); });
    }

protected:
    using RendererBase::RendererBase;

    [[nodiscard]] Films films() {
        if (albedo_.empty()) return {color_.data(), nullptr, nullptr, nullptr};
        return {color_.data(), albedo_.data(), normal_.data(), depth_.data()};
    }

private:
    [[nodiscard]] Image film_sums(Film film) const override {
        const std::vector<Vec3f>& sums = film == Film::Color    ? color_
                                         : film == Film::Albedo ? albedo_
                                         : film == Film::Normal ? normal_
                                                                : depth_;
        if (sums.empty()) return {};
        Image image(options().width, options().height);
        image.pixels = sums;
        return image;
    }

    void reset_films() override {
        const size_t pixels = size_t(options().width) * size_t(options().height);
        const auto film = [&](bool wanted) { return std::vector<Vec3f>(wanted ? pixels : 0, Vec3f(0.0f)); };
        color_ = film(true);
        albedo_ = film(options().aovs);
        normal_ = film(options().aovs);
        depth_ = film(options().aovs);
    }

    std::vector<Vec3f> color_, albedo_, normal_, depth_;
};

}  // namespace rf::cpu
