// An object's quads cut into pages (Garanzha 2014, §6.3 (b)-(d)): SAH
// branches of at most kBranchQuads quads (an SAH split recursion stopped at
// that size, so branches are well separated), each branch's quads sorted by
// the 30-bit Morton code of their centres and cut into equal blocks of
// quads_per_page; then each block quantised into its own 16-bit cube
// (§6.3.2: page bounds, the decode transform kept resident) with its own BVH
// (binned SAH, leaves of at most kPageLeafQuads quads).
//
// Watertight seams: every page of an object is quantised on one lattice
// (per axis a power-of-two step, each page's offset a lattice point), so a
// vertex shared by two pages decodes to the same point, exactly, in both:
// offset + step * q is a sum of two multiples of the step. With each page
// in its own cube (the seed's form) a shared vertex decoded to two nearby
// points, and 4.7 % of rays aimed at the vertices and edge midpoints of a
// paged closed sphere passed between them (PagedScene.RaysAtPageSeamsNeverLeak).
// The price: a page smaller than the object's largest keeps the largest's step.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "ooc/pack_format.h"
#include "ooc/quad_pairing.h"
#include "render/shading_triangles.h"

namespace rf::pack {

// A CWBVH over boxes, the form of both a page's tree (over its quads'
// boxes, in quantised space) and the top BVH (over the page references'
// world boxes): a binned SAH BVH collapsed by build_cwbvh (leaves of one to
// three boxes, octant-ordered slots, 8-bit child boxes). Leaf item k is
// box items[k]. Empty for no boxes.
struct WideTree {
    std::vector<PageNode> nodes;
    std::vector<uint32_t> items;
};
WideTree build_wide_tree(std::span<const Box3f> boxes);

// Quad indices of each page, in page order.
std::vector<std::vector<uint32_t>> partition_into_pages(std::span<const Vec3f> positions,
                                                        std::span<const QuadRef> quads, uint32_t quads_per_page);

struct BuiltPage {
    PageInfo info;                    // first_attribute_page and object left for the writer
    std::vector<uint8_t> geometry;    // the raw geometry page
    std::vector<ShadingTriangle> shading;  // 2 per quad, in the page's quad order
    double max_error = 0.0;           // largest |decoded - input| coordinate, world units
};

// The object's lattice: per axis the smallest power of two that quantises
// its largest page's half extent into kQuantMax - 1 steps.
Vec3f lattice_steps(std::span<const Vec3f> positions, std::span<const QuadRef> quads,
                    std::span<const std::vector<uint32_t>> page_quads);

BuiltPage build_page(std::span<const Vec3f> positions, std::span<const ShadingTriangle> shading,
                     std::span<const QuadRef> quads, std::span<const uint32_t> page_quads, const Vec3f& step);

// A geometry page's triangles cut into attribute pages of at most
// `page_bytes`: runs of `triangles_per_page` triangles (the last holds the
// rest). Full and Compact: page_bytes / record bytes; Shared: the most
// that keep every run's page within page_bytes.
struct AttributePages {
    uint32_t triangles_per_page = 0;
    std::vector<std::vector<uint8_t>> pages;
};
AttributePages cut_attribute_pages(std::span<const ShadingTriangle> shading, AttributeFormat format,
                                   uint32_t page_bytes);

}  // namespace rf::pack
