// Color helpers shared by both backends: the sRGB transfer function (IEC
// 61966-2-1) and Rec. 709 luminance.
#pragma once

#include <cmath>

#include "rayforge/core/host_device.h"
#include "rayforge/math/vec.h"

namespace rf {

// Encoded sRGB value in [0,1] -> linear.
RF_HDI float srgb_to_linear(float c) {
    return c <= 0.04045f ? c * (1.0f / 12.92f) : powf((c + 0.055f) * (1.0f / 1.055f), 2.4f);
}

// Linear value -> encoded sRGB; inputs outside [0,1] are clamped first.
RF_HDI float linear_to_srgb(float c) {
    c = fminf(fmaxf(c, 0.0f), 1.0f);
    return c <= 0.0031308f ? c * 12.92f : 1.055f * powf(c, 1.0f / 2.4f) - 0.055f;
}

RF_HDI Vec3f srgb_to_linear(Vec3f c) {
    return {srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z)};
}

RF_HDI Vec3f linear_to_srgb(Vec3f c) {
    return {linear_to_srgb(c.x), linear_to_srgb(c.y), linear_to_srgb(c.z)};
}

// Relative luminance of linear Rec. 709 / sRGB primaries.
RF_HDI float luminance(Vec3f c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

}  // namespace rf
