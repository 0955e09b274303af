// Filtered texture lookups shared by both backends: bilinear filtering
// between texel centres and trilinear mip-mapping (Williams 1983, "Pyramidal
// Parametrics"). A TextureView is a plain pointer view of an rf::Texture, so
// the same lookup code runs on the CPU (viewing the Scene's vectors) and on
// the GPU (viewing device copies).
//
// Convention (glTF): uv (0, 0) is the top-left corner of the image, v grows
// downwards, matching Texture's row 0 = top. The level of detail passed to the
// mip-mapped lookup is log2 of the filter footprint in level-0 texels; see
// render/texture_lod.h for where it comes from.
#pragma once

#include <cmath>
#include <cstdint>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/texture.h"
#include "math/color.h"

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
    // 256 linear values, one per 8-bit code, for the colour channels of an
    // 8-bit texture: a table lookup instead of powf per channel per texel.
    // make_texture_view points it at a host table; a device view must point
    // it at a device copy or leave it null, which falls back to the formula.
    const float* decode8 = nullptr;

    [[nodiscard]] RF_HDI bool valid() const {
        return width > 0 && height > 0 && channels >= 1 && channels <= 4 &&
               (encoding == TextureEncoding::LinearFloat ? texels_f != nullptr : texels8 != nullptr);
    }
};

// Host tables of the 8-bit decodes: srgb_to_linear(v / 255) and v / 255,
// bit-identical to the formulas fetch_texel falls back to.
const float* srgb8_decode_table();
const float* linear8_decode_table();

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
            // Power-of-two sizes (most textures) wrap with a mask instead of a division.
            if ((size & (size - 1)) == 0) return i & (size - 1);
            int m = i % size;
            return m < 0 ? m + size : m;
        }
    }
}

// The linear value of an 8-bit code by formula (what the decode tables hold).
RF_HDI float decode8_formula(uint8_t code, TextureEncoding encoding) {
    float value = float(code) * (1.0f / 255.0f);
    return encoding == TextureEncoding::Srgb8 ? srgb_to_linear(value) : value;
}

// One texel as linear RGBA. Grey textures replicate their channel, grey+alpha
// and RGB textures get the missing channels; alpha is never sRGB-decoded.
RF_HDI Vec4f fetch_texel(const TextureView& t, int x, int y) {
    size_t base = (size_t(y) * size_t(t.width) + size_t(x)) * size_t(t.channels);
    float c[4] = {0.0f, 0.0f, 0.0f, 1.0f};
    if (t.encoding == TextureEncoding::LinearFloat) {
        for (int i = 0; i < t.channels; ++i) c[i] = t.texels_f[base + i];
    } else {
        const uint8_t* texel = t.texels8 + base;
        for (int i = 0; i < t.channels; ++i) {
            bool is_alpha = (t.channels == 2 && i == 1) || i == 3;
            uint8_t code = texel[i];
            if (is_alpha) c[i] = float(code) * (1.0f / 255.0f);  // = linear8 table
            else c[i] = t.decode8 ? t.decode8[code] : decode8_formula(code, t.encoding);
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

// Level 0 plus at most 15 coarser levels: enough for a 32768-texel side.
inline constexpr int kMaxMipLevels = 16;

// A texture and its mip chain as plain views (fixed size, so it can be
// copied to the device as is; only the texel pointers need translating).
struct MipTextureView {
    TextureView levels[kMaxMipLevels];
    int level_count = 0;

    [[nodiscard]] RF_HDI const TextureView& base() const { return levels[0]; }
};

class MipChain;

// Views of `base` and of `chain`'s levels (both must outlive the view);
// a null chain gives a single level. Levels take the base's wrap modes.
MipTextureView make_mip_view(const Texture& base, const MipChain* chain);

// a + (b - a) t per channel.
RF_HDI Vec4f blend_texels(Vec4f a, Vec4f b, float t) {
    return {a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t, a.z + (b.z - a.z) * t,
            a.w + (b.w - a.w) * t};
}

// Trilinear lookup: `lod` is log2 of the footprint in level-0 texels. lod <= 0
// (or NaN) is bilinear on level 0; otherwise the two levels around lod are
// blended, and lods past the last level use the last level alone.
RF_HDI Vec4f sample_texture(const MipTextureView& t, Vec2f uv, float lod) {
    if (t.level_count <= 1 || !(lod > 0.0f)) return sample_texture(t.levels[0], uv);
    float last = float(t.level_count - 1);
    if (lod >= last) return sample_texture(t.levels[t.level_count - 1], uv);
    float fine = floorf(lod);
    float blend = lod - fine;
    // 0 <= fine < level_count - 1 here; the clamp spells that out for the
    // compiler's bounds analysis.
    int level = int(fine);
    level = level < 0 ? 0 : (level > kMaxMipLevels - 2 ? kMaxMipLevels - 2 : level);
    Vec4f a = sample_texture(t.levels[level], uv);
    if (blend <= 0.0f) return a;
    return blend_texels(a, sample_texture(t.levels[level + 1], uv), blend);
}

}  // namespace rf
