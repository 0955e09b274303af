// Writing a paged scene file (pack_format.h), object by object, out of core
// as the dissertation's preprocessor does (§6.3.1 (h)): each object's pages
// are built and written when it is added, then its memory is freed; only
// the per-page bounds and root nodes stay until finish() builds the top level over them. So the writer's memory is bounded by its largest object
// (about kWriterBytesPerTriangle per triangle) plus 144 bytes per page.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "ooc/pack_format.h"
#include "rayforge/core/progress.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/light.h"
#include "rayforge/scene/texture.h"
#include "render/material_eval.h"
#include "rayforge/math/affine.h"
#include "render/shading_triangles.h"

namespace rf::pack {

// Peak working memory of add_object per input triangle (positions,
// records, quads, sort keys, page buffers), for budgets.
inline constexpr size_t kWriterBytesPerTriangle = 400;

struct PackWriterOptions {
    Codec codec = Codec::Meshopt;
    int zstd_level = 3;
    AttributeFormat attribute_format = AttributeFormat::Shared;
    uint32_t attribute_page_bytes = kDefaultAttributePageBytes;  // a power of two, 1 KB .. 1 MB
    uint32_t quads_per_page = kQuadsPerPage;                     // 64 .. kQuadsPerPage
    TopLevel top_level = TopLevel::WideBvh;                      // how rays find pages (pack_format.h)
    bool flatten_instances = false;  // convert_scene: every instance in world space (the file then holds no instances)
    int grid_resolution = kDefaultGridResolution;                // TopLevel::Grid: 1 .. kMaxGridResolution
    int threads = 0;                                             // 0 = all cores
};

// One object: world-space positions, 3 indices per triangle, and each
// triangle's shading record (its material included) in the same order.
struct ObjectInput {
    std::span<const Vec3f> positions;
    std::span<const uint32_t> indices;
    std::span<const ShadingTriangle> shading;
};

struct PackSummary {
    uint64_t triangles = 0;          // unique (every page's triangles once)
    uint64_t instanced_triangles = 0; // placed by instances (each instance's object counted again)
    uint32_t instances = 0;
    uint64_t quads = 0;
    uint64_t paired_triangles = 0;   // triangles that found a partner
    uint32_t geometry_pages = 0;
    uint32_t attribute_pages = 0;
    uint32_t texture_pages = 0;
    uint32_t middle_nodes = 0;       // TopLevel::Grid: the cells' BVH nodes
    uint32_t top_nodes = 0;          // TopLevel::WideBvh: the top BVH's nodes
    uint64_t file_bytes = 0;
    uint64_t geometry_bytes = 0;     // stored bytes of the geometry pages
    uint64_t attribute_bytes = 0;
    uint64_t texture_bytes = 0;
    uint64_t resident_bytes = 0;
    uint64_t decoded_bytes = 0;      // every page as decoded (what caching the whole scene takes)
    double max_quantisation_error = 0.0;  // world units, over all vertices
};

class PackWriter {
public:
    // Creates (truncates) `path`; rf::Error when it cannot be written or an option is out of range.
    PackWriter(const std::string& path, const PackWriterOptions& options = {});
    ~PackWriter();
    PackWriter(const PackWriter&) = delete;
    PackWriter& operator=(const PackWriter&) = delete;

    // Materials and textures first (ids in order from 0); a material's
    // texture ids refer to add_texture's results.
    uint32_t add_material(const ShadingMaterial& material);
    // Cuts `texture` and its mip levels into tiles and writes them.
    uint32_t add_texture(const Texture& texture);
    void add_light(const Light& light);
    void set_camera(const Camera& camera);
    void set_environment(const Environment& environment);

    // Pairs, partitions, quantises and writes one object (rf::Error on
    // non-finite coordinates or out-of-range indices or materials), in
    // world space; returns its id.
    uint32_t add_object(const ObjectInput& object);
    // The same for an object placed by instances (the seed's clones): its
    // pages are written once, in the object's own space, and reached only
    // through add_instance.
    uint32_t add_instanced_object(const ObjectInput& object_space);
    // One more placement of an instanced object (rf::Error when `object` is
    // not one, or the transform is not finite or not invertible).
    void add_instance(uint32_t object, const Affine3f& world_from_object);

    // Builds the top level (pack_format.h), writes the resident section, the
    // directory and the header. Nothing may be added after it.
    PackSummary finish(const ProgressCallback& progress = {});

    [[nodiscard]] const PackSummary& summary() const;

private:
    uint32_t write_object(const ObjectInput& object, bool instanced);

    struct State;
    std::unique_ptr<State> state_;
};

}  // namespace rf::pack
