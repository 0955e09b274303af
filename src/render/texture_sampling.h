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

// The four texels a bilinear lookup reads (wrapped into the texture) and the
// weights between them. Split from the fetches so that a texture held
// elsewhere (paged: ooc/paged_texture.h) filters with the same arithmetic.
struct BilinearTaps {
    int x0 = 0, x1 = 0;  // columns
    int y0 = 0, y1 = 0;  // rows
    float wx = 0.0f, wy = 0.0f;  // weights of x1 and y1
};

// Where a bilinear lookup at uv reads in a width x height texture: between
// the centres of the texels around uv.
RF_HDI BilinearTaps bilinear_taps(int width, int height, TextureWrap wrap_s, TextureWrap wrap_t, Vec2f uv) {
    // Non-finite uv (degenerate meshes) would make the integer conversion undefined.
    // (|x| <= FLT_MAX is false for NaN and infinities, on host and device alike.)
    float u = fabsf(uv.x) <= 3.402823466e+38f ? uv.x : 0.0f;
    float v = fabsf(uv.y) <= 3.402823466e+38f ? uv.y : 0.0f;
    // Keep coordinates in a range where float -> int is exact and safe;
    // repeat modes are periodic so shifting by whole periods is harmless.
    u = fminf(fmaxf(u, -1.0e6f), 1.0e6f);
    v = fminf(fmaxf(v, -1.0e6f), 1.0e6f);
    float px = u * float(width) - 0.5f;
    float py = v * float(height) - 0.5f;
    float fx0 = floorf(px), fy0 = floorf(py);
    BilinearTaps taps;
    taps.wx = px - fx0;
    taps.wy = py - fy0;
    // |u| <= 1e6 times a side of up to 65536 texels exceeds int: clamp the
    // texel index (a coordinate that far out has no meaningful texel anyway).
    int x = int(fminf(fmaxf(fx0, -1073741824.0f), 1073741824.0f));
    int y = int(fminf(fmaxf(fy0, -1073741824.0f), 1073741824.0f));
    taps.x0 = wrap_texel(x, width, wrap_s);
    taps.x1 = wrap_texel(x + 1, width, wrap_s);
    taps.y0 = wrap_texel(y, height, wrap_t);
    taps.y1 = wrap_texel(y + 1, height, wrap_t);
    return taps;
}

// The texels (x0, y0), (x1, y0), (x0, y1), (x1, y1) blended by the taps' weights.
RF_HDI Vec4f bilinear_blend(const BilinearTaps& taps, Vec4f c00, Vec4f c10, Vec4f c01, Vec4f c11) {
    float wx = taps.wx, wy = taps.wy;
    float w00 = (1 - wx) * (1 - wy), w10 = wx * (1 - wy), w01 = (1 - wx) * wy, w11 = wx * wy;
    return {c00.x * w00 + c10.x * w10 + c01.x * w01 + c11.x * w11,
            c00.y * w00 + c10.y * w10 + c01.y * w01 + c11.y * w11,
            c00.z * w00 + c10.z * w10 + c01.z * w01 + c11.z * w11,
            c00.w * w00 + c10.w * w10 + c01.w * w01 + c11.w * w11};
}

// Bilinearly filtered linear RGBA at uv; white for an invalid view.
RF_HDI Vec4f sample_texture(const TextureView& t, Vec2f uv) {
    if (!t.valid()) return {1.0f, 1.0f, 1.0f, 1.0f};
    BilinearTaps taps = bilinear_taps(t.width, t.height, t.wrap_s, t.wrap_t, uv);
    Vec4f c00 = fetch_texel(t, taps.x0, taps.y0), c10 = fetch_texel(t, taps.x1, taps.y0);
    Vec4f c01 = fetch_texel(t, taps.x0, taps.y1), c11 = fetch_texel(t, taps.x1, taps.y1);
    return bilinear_blend(taps, c00, c10, c01, c11);
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

// The levels a trilinear lookup at `lod` reads: `level` alone when blend is
// 0, else `level` and `level` + 1 blended by `blend`. lod <= 0 (or NaN) is
// level 0; lods past the last level are the last level.
struct MipBlend {
    int level = 0;
    float blend = 0.0f;
};
RF_HDI MipBlend mip_blend(int level_count, float lod) {
    if (level_count <= 1 || !(lod > 0.0f)) return {0, 0.0f};
    float last = float(level_count - 1);
    if (lod >= last) return {level_count - 1, 0.0f};
    float fine = floorf(lod);
    // 0 <= fine < level_count - 1 here; the clamp spells that out for the
    // compiler's bounds analysis.
    int level = int(fine);
    level = level < 0 ? 0 : (level > kMaxMipLevels - 2 ? kMaxMipLevels - 2 : level);
    return {level, lod - fine};
}

// Trilinear lookup: `lod` is log2 of the footprint in level-0 texels. lod <= 0
// (or NaN) is bilinear on level 0; otherwise the two levels around lod are
// blended, and lods past the last level use the last level alone.
RF_HDI Vec4f sample_texture(const MipTextureView& t, Vec2f uv, float lod) {
    MipBlend m = mip_blend(t.level_count, lod);
    Vec4f a = sample_texture(t.levels[m.level], uv);
    if (m.blend <= 0.0f) return a;
    return blend_texels(a, sample_texture(t.levels[m.level + 1], uv), m.blend);
}

}  // namespace rf
