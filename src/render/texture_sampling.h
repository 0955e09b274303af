// Filtered texture lookups shared by both backends. A TextureView is a plain
// pointer view of an rf::Texture, so the same lookup code runs on the CPU
// (viewing the Scene's vectors) and on the GPU (viewing device copies).
//
// Convention (glTF): uv (0, 0) is the top-left corner of the image, v grows
// downwards, matching Texture's row 0 = top. Lookups are bilinear between the
// four nearest texel centres; mip-mapping is not done yet.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/texture.h"
#include "render/color.h"

namespace rf {

struct TextureView {
    int width = 0;
    int height = 0;
    int channels = 0;
    TextureEncoding encoding = TextureEncoding::Srgb8;
    TextureWrap wrap_s = TextureWrap::Repeat;
    TextureWrap wrap_t = TextureWrap::Repeat;
    const uint8_t* texels8 = nullptr;
    const float* texels_f = nullptr;

    [[nodiscard]] RF_HDI bool valid() const {
        return width > 0 && height > 0 && channels >= 1 && channels <= 4 &&
               (encoding == TextureEncoding::LinearFloat ? texels_f != nullptr : texels8 != nullptr);
    }
};

// A view of `texture`, which must outlive it; an inconsistent texture (sizes
// that disagree with its texel array) gives an invalid view, which samples as white.
TextureView make_texture_view(const Texture& texture);

// Maps an integer texel coordinate into [0, size) by the wrap mode.
RF_HDI int wrap_texel(int i, int size, TextureWrap wrap) {
    switch (wrap) {
        case TextureWrap::ClampToEdge:
            return i < 0 ? 0 : (i >= size ? size - 1 : i);
        case TextureWrap::MirroredRepeat: {
            int period = 2 * size;
            int m = i % period;
            if (m < 0) m += period;
            return m < size ? m : period - 1 - m;
        }
        case TextureWrap::Repeat:
        default: {
            int m = i % size;
            return m < 0 ? m + size : m;
        }
    }
}

// One texel as linear RGBA. Grey textures replicate their channel, grey+alpha
// and RGB textures get the missing channels; alpha is never sRGB-decoded.
RF_HDI Vec4f fetch_texel(const TextureView& t, int x, int y) {
    size_t base = (size_t(y) * size_t(t.width) + size_t(x)) * size_t(t.channels);
    float c[4] = {0.0f, 0.0f, 0.0f, 1.0f};
    for (int i = 0; i < t.channels; ++i) {
        if (t.encoding == TextureEncoding::LinearFloat) {
            c[i] = t.texels_f[base + i];
        } else {
            float value = float(t.texels8[base + i]) * (1.0f / 255.0f);
            bool is_alpha = (t.channels == 2 && i == 1) || i == 3;
            c[i] = (t.encoding == TextureEncoding::Srgb8 && !is_alpha) ? srgb_to_linear(value) : value;
        }
    }
    if (t.channels <= 2) {
        float alpha = t.channels == 2 ? c[1] : 1.0f;
        return {c[0], c[0], c[0], alpha};
    }
    return {c[0], c[1], c[2], c[3]};
}

// Bilinearly filtered linear RGBA at uv; white for an invalid view.
RF_HDI Vec4f sample_texture(const TextureView& t, Vec2f uv) {
    if (!t.valid()) return {1.0f, 1.0f, 1.0f, 1.0f};
    // Non-finite uv (degenerate meshes) would make the integer conversion undefined.
    // (|x| <= FLT_MAX is false for NaN and infinities, on host and device alike.)
    float u = fabsf(uv.x) <= 3.402823466e+38f ? uv.x : 0.0f;
    float v = fabsf(uv.y) <= 3.402823466e+38f ? uv.y : 0.0f;
    // Keep coordinates in a range where float -> int is exact and safe;
    // repeat modes are periodic so shifting by whole periods is harmless.
    u = fminf(fmaxf(u, -1.0e6f), 1.0e6f);
    v = fminf(fmaxf(v, -1.0e6f), 1.0e6f);
    float px = u * float(t.width) - 0.5f;
    float py = v * float(t.height) - 0.5f;
    float fx0 = floorf(px), fy0 = floorf(py);
    float wx = px - fx0, wy = py - fy0;
    int x0 = int(fx0), y0 = int(fy0);
    int xa = wrap_texel(x0, t.width, t.wrap_s), xb = wrap_texel(x0 + 1, t.width, t.wrap_s);
    int ya = wrap_texel(y0, t.height, t.wrap_t), yb = wrap_texel(y0 + 1, t.height, t.wrap_t);
    Vec4f c00 = fetch_texel(t, xa, ya), c10 = fetch_texel(t, xb, ya);
    Vec4f c01 = fetch_texel(t, xa, yb), c11 = fetch_texel(t, xb, yb);
    float w00 = (1 - wx) * (1 - wy), w10 = wx * (1 - wy), w01 = (1 - wx) * wy, w11 = wx * wy;
    return {c00.x * w00 + c10.x * w10 + c01.x * w01 + c11.x * w11,
            c00.y * w00 + c10.y * w10 + c01.y * w01 + c11.y * w11,
            c00.z * w00 + c10.z * w10 + c01.z * w01 + c11.z * w11,
            c00.w * w00 + c10.w * w10 + c01.w * w01 + c11.w * w11};
}

}  // namespace rf
