// The paged scene file (.rfpack), after the dissertation's out-of-core
// ray tracer (Garanzha 2014, ch. 6, §6.3; docs/paged-scenes.md has the
// byte layout). A scene is cut into pages that are read on demand:
//   - geometry pages: up to kQuadsPerPage quads (triangle pairs) with 16-bit
//     page-local quantised vertices and the page's own compressed 8-wide BVH
//     (format 2: CWBVH nodes, Ylitie et al. 2017, in the page's quantised
//     coordinates, leaves of one to three quads), the quantisation folded
//     into the page's decode transform (§6.3.2);
//   - attribute pages: the shading data of every triangle, in the quads'
//     Morton order (§6.4), in pages of at most `attribute_page_bytes`, each
//     holding a run of PageInfo::attribute_triangles triangles (Shared
//     pages: per-vertex data shared within the run; Full, Compact: a
//     fixed-size record per triangle);
//   - texture pages: 32x32-texel tiles of every mip level (§6.5).
// What is always resident (the "resident section"): per geometry page its
// world bounds, decode transform and a copy of its BVH's root node, the top level (a CWBVH over the page
// bounds, or the seed's top grid of kGridResolution^3 cells and per cell a
// BVH over the page bounds clipped to the cell, §6.3.1 (e)-(g)), the
// materials, lights, camera and texture descriptions.
//
// Every page carries a checksum of its stored bytes; the header, the page
// directory and the resident section carry their own. All integers are
// little-endian, the file's structs are plain data written as they lie in
// memory (static_asserts below pin their sizes).
#pragma once

#include <cstddef>
#include <cstdint>

#include "accel/bvh/layout/cwbvh_layout.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/box.h"
#include "rayforge/math/vec.h"

namespace rf::pack {

inline constexpr char kMagic[8] = {'R', 'F', 'P', 'A', 'C', 'K', '\r', '\n'};
// 3: shared-vertex attribute pages and per-page attribute runs
// (PageInfo::attribute_triangles), the meshopt page codec, resident page
// roots; 2: wide (CWBVH)
// page BVHs. Older files are not read: they get a "convert it again" error.
inline constexpr uint32_t kVersion = 3;

// Garanzha 2014's parameters (§6.3, §6.7.1).
inline constexpr uint32_t kQuadsPerPage = 4096;      // NP
inline constexpr uint32_t kBranchQuads = 65536;      // NB, the SAH-branch limit
inline constexpr uint32_t kPageLeafQuads = kCwbvhMaxLeafTriangles;  // quads in a page-BVH leaf (1..3)
inline constexpr uint32_t kTrianglesPerPageSlot = 2 * kQuadsPerPage;  // Hit::prim = page * this + 2 * quad + half
inline constexpr int kDefaultGridResolution = 32;    // the top grid, cells per axis
inline constexpr int kMaxGridResolution = 256;
inline constexpr uint32_t kTextureTileSide = 32;     // texels; an RGBA8 tile is 4 KB
inline constexpr uint32_t kDefaultAttributePageBytes = 8192;
inline constexpr int16_t kQuantMax = 32767;          // quantised coordinates lie in [-kQuantMax, kQuantMax]

enum class PageKind : uint8_t { Geometry = 0, Attributes = 1, TextureTile = 2 };
// Codec::Meshopt: meshoptimizer's vertex and index codecs, then zstd (ooc/page_codec.h).
enum class Codec : uint8_t { None = 0, Zstd = 1, Meshopt = 2 };
enum class AttributeFormat : uint8_t {
    Full = 0,     // 64-byte rf::ShadingTriangle records, exact
    Compact = 1,  // 32-byte CompactShading records (half-float uvs)
    Shared = 2,   // per-vertex data shared within a page (ooc/shared_attributes.h): exact but for an octahedral geometric normal
};

// At offset 0. header_checksum covers the bytes before it.
struct FileHeader {
    char magic[8];
    uint32_t version = kVersion;
    uint32_t header_bytes = sizeof(FileHeader);
    uint64_t resident_offset = 0;
    uint64_t resident_bytes = 0;
    uint64_t directory_offset = 0;
    uint64_t page_count = 0;          // directory entries: geometry, then attribute, then texture pages
    uint64_t triangle_count = 0;      // input triangles (degenerate ones included)
    uint64_t quad_count = 0;
    uint64_t file_bytes = 0;          // the whole file, to tell a truncated one
    uint32_t geometry_pages = 0;
    uint32_t attribute_pages = 0;
    uint32_t texture_pages = 0;
    uint32_t resident_checksum = 0;
    uint32_t directory_checksum = 0;
    uint32_t reserved[7] = {};
    uint32_t header_checksum = 0;
};
static_assert(sizeof(FileHeader) == 128);

// One per page, in the directory.
struct PageEntry {
    uint64_t offset = 0;        // in the file
    uint32_t stored_bytes = 0;  // as stored (compressed or not)
    uint32_t raw_bytes = 0;     // after decompression
    uint32_t checksum = 0;      // of the stored bytes
    PageKind kind = PageKind::Geometry;
    Codec codec = Codec::None;
    uint16_t reserved = 0;
};
static_assert(sizeof(PageEntry) == 24);

// A page-BVH node: a CWBVH node (accel/bvh/layout/cwbvh_layout.h, 80
// bytes) whose boxes are in the page's quantised coordinates, where
// base_index_child indexes the page's nodes and base_index_triangle its
// quads: a leaf slot's meta holds its quad count (1..3, unary) and the
// offset of its first quad from base_index_triangle. Children follow their
// parent, every node but the root has exactly one parent, and the tree is at
// most kCwbvhMaxDepth nodes deep (view_geometry_page checks all three).
using PageNode = CwbvhNode;
static_assert(sizeof(PageNode) == 80);

// Four quantised vertices. The quad is the triangles (v0, v1, v2) and
// (v0, v2, v3); an unpaired triangle repeats v0 as v3 (its second half is
// degenerate and never hit).
struct Quad {
    int16_t v[4][3];
};
static_assert(sizeof(Quad) == 24);

// A geometry page as read (raw bytes): this header, node_count PageNodes
// (node 0 the root; 16-byte aligned in a cache slot), then quad_count
// Quads in leaf order.
struct GeometryPageHeader {
    uint32_t quad_count = 0;
    uint32_t node_count = 0;
    uint32_t reserved[2] = {};
};
static_assert(sizeof(GeometryPageHeader) == 16);

// Always resident, one per geometry page: position = offset + scale *
// quantised, in world space, or in its object's space when the object is
// instanced (the seed's clones: placed by InstanceInfo transforms).
struct PageInfo {
    Box3f bounds;                    // of the decoded quads, in the space above
    Vec3f offset;
    Vec3f scale;
    uint32_t quad_count = 0;
    uint32_t first_attribute_page = 0;  // attribute pages of this page's triangles start here
    uint32_t object = 0;                // the input object it came from
    uint16_t instanced = 0;             // 1: object space, reached only through instances
    uint16_t attribute_triangles = 0;   // triangles per attribute page (the last holds the rest)
};
static_assert(sizeof(PageInfo) == 64);

// A placement of an instanced object's pages: world = world_from_object *
// object (3x4, row-major); its inverse takes rays into object space, where
// the pages' decode transform (M_encode) applies, so a ray reaches a page's
// quantised space through object_from_world then M_encode^-1, the seed's
// M_instance * M_encode^-1 read backwards. The object's pages are
// [first_page, first_page + page_count).
struct InstanceInfo {
    float world_from_object[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    float object_from_world[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};
    uint32_t object = 0;
    uint32_t first_page = 0;
    uint32_t page_count = 0;
    uint32_t reserved = 0;
};
static_assert(sizeof(InstanceInfo) == 112);

// What the top level's leaves reach: a page, as it lies (instance
// kNoInstance: a world-space page) or through an instance.
inline constexpr uint32_t kNoInstance = 0xFFFFFFFFu;
struct TopRef {
    uint32_t page = 0;
    uint32_t instance = kNoInstance;
};
static_assert(sizeof(TopRef) == 8);

// A 32-byte shading record (AttributeFormat::Compact): oct-encoded normals
// as in rf::ShadingTriangle, uvs as IEEE half floats.
struct CompactShading {
    uint32_t geometric_normal = 0;
    uint32_t material_flags = 0;  // material in the low 24 bits, ShadingTriangle flags in the high 8
    uint32_t normals[3] = {0, 0, 0};
    uint16_t uv[3][2] = {};
};
static_assert(sizeof(CompactShading) == 32);

// A texture: its levels, each cut into kTextureTileSide^2 RGBA8 tiles
// (row-major within the level); one tile per texture page.
struct TextureInfo {
    static constexpr int kMaxLevels = 16;
    uint32_t width = 0, height = 0;  // level 0
    uint32_t level_count = 0;
    uint8_t encoding = 0;            // rf::TextureEncoding (8-bit ones; float textures are stored as linear 8-bit)
    uint8_t wrap_s = 0, wrap_t = 0;  // rf::TextureWrap
    uint8_t channels = 4;            // of the source; tiles always hold 4
    uint32_t first_tile[kMaxLevels] = {};  // texture-page index (within the texture pages) of each level's tile (0, 0)
};
static_assert(sizeof(TextureInfo) == 80);

// How rays find the pages they meet, through the top references (TopRef:
// every world-space page once, every instanced object's pages once per
// instance). WideBvh (the default): one CWBVH over the references' world
// boxes, leaves of one to three references (base_index_triangle and the
// leaf offsets index top_refs, which are in leaf order). Grid: the seed's
// top grid with a BVH over the (clipped) boxes in every cell (§6.3.1
// (e)-(g)), kept so that its tables can be reproduced; its leaves index
// top_refs. A file holds one of the two (the other's arrays are empty: one
// empty cell, or no top nodes).
enum class TopLevel : uint8_t { WideBvh = 0, Grid = 1 };

// The resident section starts with this; the arrays follow in this order,
// each at an offset rounded up to 16 bytes:
//   PageInfo[geometry_pages]
//   PageNode page_roots[geometry_pages]   (a copy of each page's root node: rays test it before the page)
//   uint32_t cell_root[grid_cells]   (index into the middle nodes, or kEmptyCell)
//   BvhNode middle_nodes[middle_node_count]   (leaves of one reference each: first = its index in top_refs)
//   PageNode top_nodes[top_node_count]        (world space; node 0 the root)
//   TopRef top_refs[top_ref_count]
//   InstanceInfo instances[instance_count]
//   ShadingMaterial materials[material_count]
//   Light lights[light_count]
//   TextureInfo textures[texture_count]
struct ResidentHeader {
    Box3f bounds;                      // the scene's
    Box3f grid_bounds;                 // the top grid's (bounds, slightly padded)
    int32_t grid_res[3] = {1, 1, 1};
    uint32_t middle_node_count = 0;
    uint32_t material_count = 0;
    uint32_t light_count = 0;
    uint32_t texture_count = 0;
    uint32_t attribute_page_bytes = kDefaultAttributePageBytes;
    AttributeFormat attribute_format = AttributeFormat::Full;
    uint8_t has_camera = 0;
    TopLevel top_level = TopLevel::WideBvh;
    uint8_t reserved8 = 0;
    uint32_t object_count = 0;
    float camera[10] = {};             // eye, target, up, vfov (when has_camera)
    float camera_lens[2] = {};         // aperture radius, focus distance
    float environment[6] = {};         // colour rgb, strength, rotation, (unused)
    uint32_t top_node_count = 0;       // TopLevel::WideBvh: nodes of the top BVH
    uint32_t top_ref_count = 0;
    uint32_t instance_count = 0;
    uint32_t instanced_triangles[2] = {};  // low, high 32 bits: the triangles the instances place
    uint32_t reserved[3] = {};
};
static_assert(sizeof(ResidentHeader) == 192);
inline constexpr uint32_t kEmptyCell = 0xFFFFFFFFu;

// Bytes of one attribute record (Full, Compact; a Shared page has no fixed-size records: 0).
[[nodiscard]] RF_HDI uint32_t attribute_record_bytes(AttributeFormat f) {
    return f == AttributeFormat::Full ? 64u : f == AttributeFormat::Compact ? 32u : 0u;
}

// Checksum of page and section bytes: CRC-32C (Castagnoli), table-driven.
uint32_t crc32c(const void* data, size_t bytes, uint32_t seed = 0);

}  // namespace rf::pack
