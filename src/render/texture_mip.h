// Mip-maps (Williams 1983, "Pyramidal Parametrics"): the chain of
// successively halved copies of a texture that trilinear lookups blend
// between, built on the host once per texture.
#pragma once

#include <cstddef>
#include <vector>

#include "rayforge/scene/texture.h"

namespace rf {

class MipChain {
public:
    // Box-filters `base` down to 1x1. Each level halves both sides (rounding
    // down, never below 1); an odd side is filtered with a box of 2.x source
    // texels weighted by coverage, so every level keeps the base's average.
    // Filtering happens in linear space: sRGB colour channels are decoded,
    // averaged and re-encoded; alpha, Linear8 and float data are averaged as
    // stored. Every level is computed from the previous one before rounding
    // to 8 bits, so rounding errors do not pile up down the chain. An
    // inconsistent base (see make_texture_view) gets no levels.
    explicit MipChain(const Texture& base);

    // Levels 1..n (level 0 is the base itself); level n is 1x1 unless the
    // base is so large that the view's level cap is reached first.
    [[nodiscard]] const std::vector<Texture>& levels() const { return levels_; }
    // Texel bytes of levels 1..n (the base is not counted).
    [[nodiscard]] size_t memory_bytes() const;

private:
    std::vector<Texture> levels_;
};

}  // namespace rf
