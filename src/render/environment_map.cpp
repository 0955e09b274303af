// Builds the piecewise-constant distribution of an equirectangular map
// (PBRT 3rd ed. §14.2.4). Each cell's weight is the exact average of the
// bilinearly filtered luminance over the cell, so every direction where the
// map has light gets a non-zero density (a texel's light bleeds half a texel
// into its neighbours, and a black neighbour must still be sampled there).
#include "render/environment_map.h"

#include <algorithm>
#include <cmath>

namespace rf {
namespace {

constexpr double kPiD = 3.14159265358979323846;

// Luminance of one texel, clamped to be a usable weight.
float texel_weight(const TextureView& map, int x, int y) {
    Vec4f c = fetch_texel(map, x, y);
    float l = luminance(Vec3f(c.x, c.y, c.z));
    return std::isfinite(l) && l > 0.0f ? l : 0.0f;
}

// Row y of the luminance blurred horizontally with the 1D cell-average
// weights of linear interpolation (1/8, 3/4, 1/8), repeating in u.
void blurred_row(const TextureView& map, int y, std::vector<float>& out) {
    const int w = map.width;
    std::vector<float> l(size_t(w), 0.0f);
    for (int x = 0; x < w; ++x) l[size_t(x)] = texel_weight(map, x, y);
    out.resize(size_t(w));
    for (int x = 0; x < w; ++x) {
        float left = l[size_t(wrap_texel(x - 1, w, TextureWrap::Repeat))];
        float right = l[size_t(wrap_texel(x + 1, w, TextureWrap::Repeat))];
        out[size_t(x)] = 0.125f * left + 0.75f * l[size_t(x)] + 0.125f * right;
    }
}

// [begin, end) of the fine cells that coarse cell i of n overlaps, out of `fine`.
void covered_range(int i, int n, int fine, int& begin, int& end) {
    begin = int(int64_t(i) * fine / n);
    end = int((int64_t(i + 1) * fine + n - 1) / n);
    if (end <= begin) end = begin + 1;
}

}  // namespace

EnvironmentDistribution::EnvironmentDistribution(const Scene& scene, int max_width) {
    const Environment& env = scene.environment;
    base_.constant = env.color;
    base_.strength = env.strength;
    base_.rotation_radians = env.rotation_radians;
    if (env.texture < 0 || size_t(env.texture) >= scene.textures.size()) return;
    TextureView map = make_texture_view(scene.textures[size_t(env.texture)]);
    if (!map.valid()) return;  // an unusable map shows the constant colour, as the camera sees it
    map.wrap_s = TextureWrap::Repeat;       // around the horizon
    map.wrap_t = TextureWrap::ClampToEdge;  // no bleeding across the poles
    base_.map = map;

    const int fine_w = map.width, fine_h = map.height;
    max_width = std::max(max_width, 2);
    const int w = std::min(fine_w, max_width);
    const int h = std::min(fine_h, std::max(1, max_width / 2));

    // Cell averages of the bilinear luminance, the 3x3 kernel applied
    // separably with rows streamed so a huge map needs no full-size copy;
    // columns are reduced to the distribution's width as rows are produced.
    std::vector<float> coarse_columns(size_t(fine_h) * size_t(w));
    std::vector<float> above, here, below;
    std::vector<float> cell(static_cast<size_t>(fine_w));
    blurred_row(map, 0, here);
    above = here;  // clamp in v
    double luminance_integral = 0.0;  // of L over the sphere
    for (int y = 0; y < fine_h; ++y) {
        blurred_row(map, std::min(y + 1, fine_h - 1), below);
        double sum_above = 0.0, sum_here = 0.0, sum_below = 0.0;
        for (int x = 0; x < fine_w; ++x) {
            size_t i = size_t(x);
            cell[i] = 0.125f * above[i] + 0.75f * here[i] + 0.125f * below[i];
            sum_above += above[i];
            sum_here += here[i];
            sum_below += below[i];
        }
        // The row's mean over u varies linearly in v between row centres;
        // integrate it against sin(theta) dtheta with a fine midpoint rule.
        const int steps = 16;
        for (int k = 0; k < steps; ++k) {
            double t = (k + 0.5) / steps, s = t - 0.5;
            double mean = s < 0.0 ? sum_here * (1.0 + s) - sum_above * s : sum_here * (1.0 - s) + sum_below * s;
            luminance_integral += mean / fine_w * std::sin(kPiD * (y + t) / fine_h) * (kPiD / fine_h / steps) * 2.0 * kPiD;
        }
        for (int c = 0; c < w; ++c) {
            int begin, end;
            covered_range(c, w, fine_w, begin, end);
            double s = 0.0;
            for (int x = begin; x < end; ++x) s += cell[size_t(x)];
            coarse_columns[size_t(y) * size_t(w) + size_t(c)] = float(s / (end - begin));
        }
        above.swap(here);
        here.swap(below);
    }
    base_.average_luminance = float(luminance_integral / (4.0 * kPiD));

    // Rows reduced to the distribution's height, weighted by sin(theta) at
    // the row's centre, and turned into the conditional and marginal tables.
    conditional_cdf_.assign(size_t(h) * size_t(w + 1), 0.0f);
    std::vector<double> row_power(static_cast<size_t>(h), 0.0);
    std::vector<double> weights(static_cast<size_t>(w));
    for (int r = 0; r < h; ++r) {
        int begin, end;
        covered_range(r, h, fine_h, begin, end);
        double sin_theta = std::sin(kPiD * (r + 0.5) / h);
        double sum = 0.0;
        for (int c = 0; c < w; ++c) {
            double s = 0.0;
            for (int y = begin; y < end; ++y) s += coarse_columns[size_t(y) * size_t(w) + size_t(c)];
            weights[size_t(c)] = s / (end - begin) * sin_theta;
            sum += weights[size_t(c)];
        }
        float* cdf = conditional_cdf_.data() + size_t(r) * size_t(w + 1);
        double running = 0.0;
        for (int c = 0; c < w; ++c) {
            running += weights[size_t(c)];
            // A black row is never chosen; a uniform table keeps its lookups harmless.
            cdf[c + 1] = sum > 0.0 ? float(running / sum) : float(c + 1) / float(w);
        }
        cdf[w] = 1.0f;
        row_power[size_t(r)] = sum;
    }
    double total = 0.0;
    for (double p : row_power) total += p;
    if (!(total > 0.0) || !std::isfinite(total)) {
        conditional_cdf_.clear();
        return;  // black map: nothing to importance-sample
    }
    marginal_cdf_.assign(size_t(h) + 1, 0.0f);
    double running = 0.0;
    for (int r = 0; r < h; ++r) {
        running += row_power[size_t(r)];
        marginal_cdf_[size_t(r) + 1] = float(running / total);
    }
    marginal_cdf_[size_t(h)] = 1.0f;
    base_.width = w;
    base_.height = h;
}

EnvironmentLight EnvironmentDistribution::light() const {
    EnvironmentLight light = base_;
    if (!marginal_cdf_.empty()) {
        light.marginal_cdf = marginal_cdf_.data();
        light.conditional_cdf = conditional_cdf_.data();
    } else {
        light.width = light.height = 0;
    }
    return light;
}

}  // namespace rf
