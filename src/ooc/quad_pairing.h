// Triangles paired into quads (Garanzha 2014, §6.3.2; Garanzha, Bely and
// Galaktionov 2011): two triangles that share an edge and a material become
// one quad of 4 vertices, 1.5x less connectivity than two triangles. Among
// a triangle's candidates the one giving the shortest quad perimeter wins
// (the dissertation's "smallest length of quad sides"); greedily, in
// triangle order, so the result is deterministic. A triangle left without a
// partner becomes a quad whose second half is degenerate.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/math/vec.h"

namespace rf::pack {

// A quad as input vertices: triangles (v[0], v[1], v[2]) and (v[0], v[2], v[3]).
// first/second: the input triangles (second == kNoTriangle when unpaired,
// then v[3] == v[0]); rotation tells which input vertex each corner is.
struct QuadRef {
    static constexpr uint32_t kNoTriangle = 0xFFFFFFFFu;
    uint32_t v[4];
    uint32_t first = 0;
    uint32_t second = kNoTriangle;
    // Corner k of half h is vertex corner_of[h][k] (0..2) of that half's input triangle.
    uint8_t corner_of[2][3] = {{0, 1, 2}, {0, 1, 2}};
};

// `material` has one entry per triangle (3 indices each in `indices`).
std::vector<QuadRef> pair_triangles(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                                    std::span<const uint32_t> material);

}  // namespace rf::pack
