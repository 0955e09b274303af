// An object's quads cut into pages (Garanzha 2014, §6.3 (b)-(d)): SAH
// branches of at most kBranchQuads quads (an SAH split recursion stopped at
// that size, so branches are well separated), each branch's quads sorted by
// the 30-bit Morton code of their centres and cut into equal blocks of
// quads_per_page; then each block quantised into its own 16-bit cube
// (§6.3.2: page bounds, the decode transform kept resident) with its own BVH
// (binned SAH, leaves of at most kPageLeafQuads quads).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ooc/pack_format.h"
#include "ooc/quad_pairing.h"
#include "render/shading_triangles.h"

namespace rf::pack {

// Quad indices of each page, in page order.
std::vector<std::vector<uint32_t>> partition_into_pages(std::span<const Vec3f> positions,
                                                        std::span<const QuadRef> quads, uint32_t quads_per_page);

struct BuiltPage {
    PageInfo info;                    // first_attribute_page and object left for the writer
    std::vector<uint8_t> geometry;    // the raw geometry page
    std::vector<uint8_t> attributes;  // 2 records per quad, in the page's quad order
    double max_error = 0.0;           // largest |decoded - input| coordinate, world units
};

BuiltPage build_page(std::span<const Vec3f> positions, std::span<const ShadingTriangle> shading,
                     std::span<const QuadRef> quads, std::span<const uint32_t> page_quads, AttributeFormat format);

}  // namespace rf::pack
