// Mip chain construction: coverage-weighted box filtering in linear space
// (Williams 1983; an odd side is filtered with a box of w / floor(w/2) source
// texels, so no texel is dropped and every level keeps the base's average).
#include "render/texture_mip.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <utility>

#include "math/color.h"
#include "render/texture_sampling.h"

namespace rf {
namespace {

// The source texels one destination texel covers along one axis, with the
// fraction of the destination texel each one fills (the weights sum to 1).
struct AxisFootprint {
    int first = 0;
    int count = 0;
    float weight[4] = {0, 0, 0, 0};
};

// Destination texel x covers source interval [x s, (x+1) s) with
// s = source / dest; in units of 1/dest texel everything is an integer, so the
// weights are exact and no spurious slivers appear at the ends.
std::vector<AxisFootprint> axis_footprints(int source, int dest) {
    std::vector<AxisFootprint> out(static_cast<size_t>(dest));
    for (int x = 0; x < dest; ++x) {
        int64_t lo = int64_t(x) * source, hi = int64_t(x + 1) * source;
        AxisFootprint& f = out[size_t(x)];
        f.first = int(lo / dest);
        int last = int((hi - 1) / dest);
        f.count = last - f.first + 1;  // dest = floor(source / 2) or 1 gives at most 4
        for (int i = 0; i < f.count; ++i) {
            int64_t texel_lo = int64_t(f.first + i) * dest, texel_hi = texel_lo + dest;
            int64_t overlap = (hi < texel_hi ? hi : texel_hi) - (lo > texel_lo ? lo : texel_lo);
            f.weight[i] = float(double(overlap) / double(source));
        }
    }
    return out;
}

bool is_alpha_channel(int channels, int i) { return (channels == 2 && i == 1) || i == 3; }

// Horizontal pass of one row: `Channels` is a template parameter so the
// per-texel channel loop unrolls.
template <int Channels>
void filter_row(const float* source, const std::vector<AxisFootprint>& columns, float* dest) {
    for (size_t x = 0; x < columns.size(); ++x) {
        const AxisFootprint& col = columns[x];
        float sum[Channels] = {};
        for (int i = 0; i < col.count; ++i) {
            const float* texel = source + size_t(col.first + i) * Channels;
            for (int c = 0; c < Channels; ++c) sum[c] += col.weight[i] * texel[c];
        }
        for (int c = 0; c < Channels; ++c) dest[x * Channels + c] = sum[c];
    }
}

// Box-filters a width x height image of linear values to dest_w x dest_h.
// `linear_row(y, buffer)` returns row y as width * channels linear floats
// (writing into `buffer` when it has to decode).
template <class LinearRow>
std::vector<float> downsample(int width, int height, int channels, int dest_w, int dest_h,
                              const LinearRow& linear_row) {
    std::vector<AxisFootprint> columns = axis_footprints(width, dest_w);
    std::vector<AxisFootprint> rows = axis_footprints(height, dest_h);
    size_t row_floats = size_t(width) * size_t(channels);
    size_t dest_row_floats = size_t(dest_w) * size_t(channels);
    std::vector<float> out(dest_row_floats * size_t(dest_h));
    std::vector<float> decoded(row_floats), blended(row_floats);
    for (int y = 0; y < dest_h; ++y) {
        // Vertical pass: the weighted sum of the covered source rows.
        const AxisFootprint& row = rows[size_t(y)];
        for (int j = 0; j < row.count; ++j) {
            const float* source = linear_row(row.first + j, decoded.data());
            float w = row.weight[j];
            if (j == 0) {
                for (size_t k = 0; k < row_floats; ++k) blended[k] = w * source[k];
            } else {
                for (size_t k = 0; k < row_floats; ++k) blended[k] += w * source[k];
            }
        }
        float* dest = out.data() + size_t(y) * dest_row_floats;
        switch (channels) {
            case 1: filter_row<1>(blended.data(), columns, dest); break;
            case 2: filter_row<2>(blended.data(), columns, dest); break;
            case 3: filter_row<3>(blended.data(), columns, dest); break;
            default: filter_row<4>(blended.data(), columns, dest); break;
        }
    }
    return out;
}

// Rounding a linear value to the nearest sRGB code (rounding in encoded
// space) without a powf per channel: the code is the number of code midpoints
// (in linear space) at or below the value. A bucket table gives a lower bound
// and a step or two over the midpoints finishes it.
class SrgbQuantizer {
public:
    SrgbQuantizer() {
        for (int k = 0; k < 255; ++k) {
            double encoded = (k + 0.5) / 255.0;
            midpoints_[size_t(k)] = float(encoded <= 0.04045 ? encoded / 12.92
                                                             : std::pow((encoded + 0.055) / 1.055, 2.4));
        }
        int code = 0;
        for (int b = 0; b < kBuckets; ++b) {
            float bucket_start = float(b) / float(kBuckets);
            while (code < 255 && midpoints_[size_t(code)] <= bucket_start) ++code;
            first_code_[size_t(b)] = uint8_t(code);
        }
    }

    [[nodiscard]] uint8_t operator()(float linear) const {
        if (!(linear > 0.0f)) return 0;
        if (linear >= 1.0f) return 255;
        int code = first_code_[size_t(linear * float(kBuckets))];
        while (code < 255 && midpoints_[size_t(code)] <= linear) ++code;
        return uint8_t(code);
    }

private:
    // Fine enough that a bucket holds at most a couple of midpoints even at
    // the steep dark end (code steps of 1 / (255 * 12.92) in linear space).
    static constexpr int kBuckets = 4096;
    std::array<float, 255> midpoints_{};
    std::array<uint8_t, kBuckets> first_code_{};
};

uint8_t quantize_linear8(float value) { return uint8_t(lrintf(fminf(fmaxf(value, 0.0f), 1.0f) * 255.0f)); }

}  // namespace

MipChain::MipChain(const Texture& base) {
    TextureView base_view = make_texture_view(base);
    if (!base_view.valid()) return;
    const int channels = base.channels;
    const bool is_float = base.encoding == TextureEncoding::LinearFloat;
    const bool is_srgb = base.encoding == TextureEncoding::Srgb8;

    // Level 1 reads the base (8-bit rows decoded through the tables); later
    // levels read the previous level's unrounded linear values, so 8-bit
    // rounding does not accumulate down the chain.
    const float* tables[4];
    for (int c = 0; c < 4; ++c)
        tables[c] = (is_srgb && !is_alpha_channel(channels, c)) ? srgb8_decode_table() : linear8_decode_table();
    const size_t base_row_values = size_t(base.width) * size_t(channels);
    auto base_row = [&](int y, float* buffer) -> const float* {
        size_t start = size_t(y) * base_row_values;
        if (is_float) return base.texels_f.data() + start;
        const uint8_t* codes = base.texels8.data() + start;
        for (size_t k = 0; k < base_row_values; k += size_t(channels))
            for (int c = 0; c < channels; ++c) buffer[k + size_t(c)] = tables[c][codes[k + size_t(c)]];
        return buffer;
    };

    static const SrgbQuantizer srgb_quantizer;
    int width = base.width, height = base.height;
    std::vector<float> previous;
    while ((width > 1 || height > 1) && int(levels_.size()) < kMaxMipLevels - 1) {
        int dest_w = width > 1 ? width / 2 : 1;
        int dest_h = height > 1 ? height / 2 : 1;
        size_t row_values = size_t(width) * size_t(channels);
        std::vector<float> linear =
            levels_.empty()
                ? downsample(width, height, channels, dest_w, dest_h, base_row)
                : downsample(width, height, channels, dest_w, dest_h,
                             [&](int y, float*) -> const float* { return previous.data() + size_t(y) * row_values; });
        Texture level;
        level.name = base.name;
        level.width = dest_w;
        level.height = dest_h;
        level.channels = channels;
        level.encoding = base.encoding;
        level.wrap_s = base.wrap_s;
        level.wrap_t = base.wrap_t;
        if (is_float) {
            level.texels_f = linear;
        } else {
            level.texels8.resize(linear.size());
            bool srgb[4];
            for (int c = 0; c < 4; ++c) srgb[c] = is_srgb && !is_alpha_channel(channels, c);
            for (size_t k = 0; k < linear.size(); k += size_t(channels)) {
                for (int c = 0; c < channels; ++c) {
                    float value = linear[k + size_t(c)];
                    level.texels8[k + size_t(c)] = srgb[c] ? srgb_quantizer(value) : quantize_linear8(value);
                }
            }
        }
        levels_.push_back(std::move(level));
        previous = std::move(linear);
        width = dest_w;
        height = dest_h;
    }
}

size_t MipChain::memory_bytes() const {
    size_t bytes = 0;
    for (const Texture& level : levels_) bytes += level.memory_bytes();
    return bytes;
}

}  // namespace rf
