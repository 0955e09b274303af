// Shared-vertex attribute pages (AttributeFormat::Shared, the default): the
// shading data of a run of a geometry page's triangles, with the per-corner
// data (shading normal, uv) stored once per distinct vertex of the run and
// referenced by 16-bit indices, the per-triangle data (geometric normal,
// uv/area ratio, flags, a slot in the run's material palette, the tangent
// when any triangle of the run has one) once per triangle. A record decodes
// to the ShadingTriangle a Full page stores, exactly but for the geometric
// normal (octahedral with 12-bit halves: within 0.06 degrees, about what the
// page's 16-bit vertices already change) and the uv/area ratio (within
// 0.14 %), in a fifth of the bytes (a vertex is shared by up to six
// triangles).
//
// Raw page layout (every array 4-byte aligned; counts from the header):
//   SharedPageHeader
//   uint32_t materials[material_count]        (ShadingTriangle::material)
//   SharedVertex vertices[vertex_count]
//   SharedTriangle triangles[triangle_count]
//   uint16_t corners[3 * triangle_count]      (vertex indices, padded to 4 bytes)
//   uint32_t tangents[triangle_count]         (only when has_tangents)
// The writer chooses per geometry page how many triangles a page holds
// (PageInfo::attribute_triangles): the most that keep every run within
// the file's attribute page size.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "ooc/pack_format.h"
#include "render/shading_triangles.h"

namespace rf::pack {

struct SharedPageHeader {
    uint16_t triangle_count = 0;
    uint16_t vertex_count = 0;
    uint16_t material_count = 0;
    uint8_t has_tangents = 0;
    uint8_t reserved = 0;
};
static_assert(sizeof(SharedPageHeader) == 8);

struct SharedVertex {
    uint32_t normal = 0;  // octahedral, as ShadingTriangle::normals
    float uv[2] = {0, 0};
};
static_assert(sizeof(SharedVertex) == 12);

struct SharedTriangle {
    uint32_t geometric_normal = 0;  // octahedral, 2 x 12 significant bits (within 0.06 degrees)
    uint16_t uv_area_log = 0;       // encode_uv_area_ratio
    uint8_t material_slot = 0;      // into the page's materials (a run has at most 256)
    uint8_t flags = 0;              // ShadingTriangle::flags
};
static_assert(sizeof(SharedTriangle) == 8);

// The uv/area ratio (texture-space over world-space area: mip selection)
// as 256 * (log2(ratio) + 128), rounded, in 1..65535; 0 for no ratio. The
// decoded ratio is within 0.14 % (a thousandth of a mip level).
[[nodiscard]] uint16_t encode_uv_area_ratio(float ratio);
[[nodiscard]] float decode_uv_area_ratio(uint16_t code);

// Where each array of a shared page starts, from its header.
struct SharedPageLayout {
    size_t materials = 0, vertices = 0, triangles = 0, corners = 0, tangents = 0, bytes = 0;
};
[[nodiscard]] SharedPageLayout shared_page_layout(const SharedPageHeader& h);

// A page holding `triangles` (at most 65535 of them, 65535 distinct
// vertices and 256 distinct materials; rf::Error beyond).
[[nodiscard]] std::vector<uint8_t> encode_shared_page(std::span<const ShadingTriangle> triangles);

// Bytes encode_shared_page would write, without writing them; SIZE_MAX
// for a run of more than 256 materials (which no page holds).
[[nodiscard]] size_t shared_page_bytes(std::span<const ShadingTriangle> triangles);

// Record `triangle` of a page check_shared_page accepted.
[[nodiscard]] ShadingTriangle decode_shared_record(const uint8_t* page, uint32_t triangle);

// "" when `page` is a well-formed shared page of `triangle_count` triangles
// whose materials are below `material_count`; what is wrong otherwise.
[[nodiscard]] std::string check_shared_page(std::span<const uint8_t> page, uint32_t triangle_count,
                                            uint32_t material_count);

}  // namespace rf::pack
