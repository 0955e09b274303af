// Texture level of detail from ray cones: Akenine-Moller, Nilsson,
// Andersson, Barre-Brisebois, Toth, Karras 2019, "Texture Level of Detail
// Strategies for Real-Time Ray Tracing" (Ray Tracing Gems, ch. 20).
//
// A cone around each ray models the pixel footprint: its width grows by the
// spread angle per unit distance, so a distant hit covers more texels and
// reads a coarser mip level. At a hit the level is
//   lod = 0.5 log2(uv area / world area)        (texel density of the triangle)
//       + log2(|cone width| / |cos incidence|)  (footprint on the surface)
//       + 0.5 log2(texture width * height)      (uv -> texels, per texture)
// The first two terms do not depend on the texture (texture_lod_base); the
// last is added per lookup (texture_level).
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"
#include "render/texture_sampling.h"

namespace rf {

struct RayCone {
    float width = 0.0f;   // footprint diameter at the ray's origin
    float spread = 0.0f;  // growth of the width per unit distance (radians)

    // The cone where the ray has travelled `distance`.
    [[nodiscard]] RF_HDI RayCone propagate(float distance) const {
        return {width + spread * distance, spread};
    }
};

// Spread angle of a primary ray: the angle one pixel subtends at the centre
// of an image `image_height` pixels tall with vertical field of view `vfov`.
RF_HDI float pixel_spread_angle(float vfov_radians, int image_height) {
    return atanf(2.0f * tanf(0.5f * vfov_radians) / float(image_height > 0 ? image_height : 1));
}

// 0.5 log2(uv area / world area) of the triangle (p0, p1, p2) with texture
// coordinates (t0, t1, t2). -inf (finest level) when either area is zero or
// not finite: no meaningful texel density exists there.
RF_HDI float uv_density_log2(Vec3f p0, Vec3f p1, Vec3f p2, Vec2f t0, Vec2f t1, Vec2f t2) {
    Vec2f a = t1 - t0, b = t2 - t0;
    float uv_area2 = fabsf(a.x * b.y - a.y * b.x);          // twice the uv area
    float world_area2 = length(cross(p1 - p0, p2 - p0));    // twice the world area
    float ratio = uv_area2 / world_area2;
    if (!(uv_area2 > 0.0f) || !(world_area2 > 0.0f) || !(ratio <= 3.402823466e+38f)) return -INFINITY;
    return 0.5f * log2f(ratio);
}

// The texture-independent part of the level: density plus the log2 of the
// cone's footprint on the surface, which widens as 1/|cos| at grazing angles
// (clamped so that a grazing hit does not jump to the coarsest level).
// A zero width gives -inf, the finest level.
RF_HDI float texture_lod_base(float uv_density_log2, float cone_width, float cos_incidence) {
    return uv_density_log2 + log2f(fabsf(cone_width) / fmaxf(fabsf(cos_incidence), 1e-2f));
}

// The level of detail (log2 footprint in level-0 texels) of a texture whose
// level 0 is width x height texels (in memory or paged: ooc/paged_texture.h).
RF_HDI float texture_level(int width, int height, float lod_base) {
    return lod_base + 0.5f * log2f(float(width) * float(height));
}
RF_HDI float texture_level(const MipTextureView& t, float lod_base) {
    return texture_level(t.base().width, t.base().height, lod_base);
}

}  // namespace rf
