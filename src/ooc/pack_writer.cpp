// Writing a paged scene file: pages are built in parallel per object and
// written in page order, so the file is the same whatever the thread count.
#include "ooc/pack_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "ooc/page_builder.h"
#include "ooc/page_codec.h"
#include "ooc/quad_pairing.h"
#include "ooc/top_grid.h"
#include "rayforge/core/error.h"
#include "render/texture_mip.h"

namespace rf::pack {

namespace {

size_t round16(size_t n) { return (n + 15) & ~size_t(15); }

void check_options(const PackWriterOptions& o) {
    const uint32_t a = o.attribute_page_bytes;
    if (a < 1024 || a > (1u << 20) || (a & (a - 1)) != 0)
        throw Error("paged scene writer: attribute page size must be a power of two in [1024, 1048576], got " +
                    std::to_string(a));
    if (o.quads_per_page < 64 || o.quads_per_page > kQuadsPerPage)
        throw Error("paged scene writer: quads per page must be in [64, " + std::to_string(kQuadsPerPage) + "], got " +
                    std::to_string(o.quads_per_page));
    if (o.grid_resolution < 1 || o.grid_resolution > kMaxGridResolution)
        throw Error("paged scene writer: grid resolution must be in [1, " + std::to_string(kMaxGridResolution) +
                    "], got " + std::to_string(o.grid_resolution));
    if (uint8_t(o.codec) > uint8_t(Codec::Meshopt) || uint8_t(o.attribute_format) > uint8_t(AttributeFormat::Shared))
        throw Error("paged scene writer: unknown codec or attribute format");
    if (o.codec != Codec::None && (o.zstd_level < 1 || o.zstd_level > 19))
        throw Error("paged scene writer: zstd level must be in [1, 19], got " + std::to_string(o.zstd_level));
}

void check_object(const ObjectInput& object, size_t material_count) {
    if (object.indices.size() % 3 != 0 || object.shading.size() != object.indices.size() / 3)
        throw Error("paged scene writer: an object needs 3 indices and one shading record per triangle");
    for (const Vec3f& p : object.positions)
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
            throw Error("paged scene writer: an object has a non-finite vertex coordinate");
    for (uint32_t i : object.indices)
        if (i >= object.positions.size())
            throw Error("paged scene writer: index " + std::to_string(i) + " is past the object's " +
                        std::to_string(object.positions.size()) + " vertices");
    for (const ShadingTriangle& s : object.shading)
        if (s.material >= std::max<size_t>(material_count, 1))
            throw Error("paged scene writer: material " + std::to_string(s.material) + " was not added");
}

// A texture's texels at `level` as RGBA8 (float data clamped to [0, 1] and stored as linear 8-bit).
std::vector<uint8_t> rgba8(const Texture& t) {
    std::vector<uint8_t> out(size_t(t.width) * size_t(t.height) * 4);
    for (size_t i = 0; i < size_t(t.width) * size_t(t.height); ++i) {
        uint8_t c[4] = {0, 0, 0, 255};
        for (int k = 0; k < t.channels; ++k) {
            const size_t at = i * size_t(t.channels) + size_t(k);
            c[k] = t.encoding == TextureEncoding::LinearFloat
                       ? uint8_t(std::lround(std::clamp(t.texels_f[at], 0.0f, 1.0f) * 255.0f))
                       : t.texels8[at];
        }
        if (t.channels == 1) c[1] = c[2] = c[0];
        if (t.channels == 2) {
            c[3] = c[1];
            c[1] = c[2] = c[0];
        }
        std::memcpy(&out[i * 4], c, 4);
    }
    return out;
}

}  // namespace

struct PackWriter::State {
    std::string path;
    PackWriterOptions options;
    int fd = -1;
    uint64_t end = sizeof(FileHeader);
    std::vector<PageEntry> geometry_entries, attribute_entries, texture_entries;
    std::vector<PageInfo> pages;
    std::vector<PageNode> page_roots;  // a copy of each page's root node
    struct ObjectPages {
        uint32_t first_page = 0, page_count = 0;
        uint64_t triangles = 0;
        bool instanced = false;
    };
    std::vector<ObjectPages> object_pages;  // by object id
    std::vector<TopRef> refs;               // what the top level will reach, in the order added
    std::vector<InstanceInfo> instances;
    std::vector<ShadingMaterial> materials;
    std::vector<Light> lights;
    std::vector<TextureInfo> textures;
    ResidentHeader resident;
    uint32_t objects = 0;
    bool finished = false;
    PackSummary summary;

    ~State() {
        if (fd >= 0) ::close(fd);
    }

    void write_at(const void* data, size_t bytes, uint64_t offset) {
        const auto* p = static_cast<const uint8_t*>(data);
        while (bytes > 0) {
            const ssize_t n = ::pwrite(fd, p, bytes, off_t(offset));
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) throw file_error(path, 0, std::string("cannot write: ") + std::strerror(errno));
            p += n;
            bytes -= size_t(n);
            offset += uint64_t(n);
        }
    }
    PageEntry append(const StoredPage& page, PageKind kind) {
        PageEntry e;
        e.offset = end;
        e.stored_bytes = uint32_t(page.bytes.size());
        e.raw_bytes = page.raw_bytes;
        e.checksum = crc32c(page.bytes.data(), page.bytes.size());
        e.kind = kind;
        e.codec = page.codec;
        summary.decoded_bytes += page.raw_bytes;
        write_at(page.bytes.data(), page.bytes.size(), end);
        end += page.bytes.size();
        return e;
    }
    void require_open(const char* what) const {
        if (finished) throw Error(std::string("paged scene writer: ") + what + " after finish()");
    }
};

PackWriter::PackWriter(const std::string& path, const PackWriterOptions& options) : state_(std::make_unique<State>()) {
    check_options(options);
    state_->path = path;
    state_->options = options;
    state_->resident.attribute_page_bytes = options.attribute_page_bytes;
    state_->resident.attribute_format = options.attribute_format;
    state_->fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (state_->fd < 0) throw file_error(path, 0, std::string("cannot create: ") + std::strerror(errno));
}

PackWriter::~PackWriter() = default;

uint32_t PackWriter::add_material(const ShadingMaterial& material) {
    state_->require_open("add_material");
    state_->materials.push_back(material);
    return uint32_t(state_->materials.size() - 1);
}

void PackWriter::add_light(const Light& light) {
    state_->require_open("add_light");
    state_->lights.push_back(light);
}

void PackWriter::set_camera(const Camera& c) {
    ResidentHeader& r = state_->resident;
    const float values[10] = {c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z,
                              c.up.x,  c.up.y,  c.up.z,  c.vfov_degrees};
    std::copy(values, values + 10, r.camera);
    r.camera_lens[0] = c.aperture_radius;
    r.camera_lens[1] = c.focus_distance;
    r.has_camera = 1;
}

void PackWriter::set_environment(const Environment& e) {
    float* out = state_->resident.environment;
    out[0] = e.color.x;
    out[1] = e.color.y;
    out[2] = e.color.z;
    out[3] = e.strength;
    out[4] = e.rotation_radians;
}

uint32_t PackWriter::add_texture(const Texture& texture) {
    State& s = *state_;
    s.require_open("add_texture");
    if (texture.width <= 0 || texture.height <= 0 || texture.width > 65536 || texture.height > 65536 ||
        texture.channels < 1 || texture.channels > 4)
        throw Error("paged scene writer: texture '" + texture.name + "' has bad dimensions");
    const MipChain chain(texture);
    TextureInfo info;
    info.width = uint32_t(texture.width);
    info.height = uint32_t(texture.height);
    info.encoding = uint8_t(texture.encoding == TextureEncoding::LinearFloat ? TextureEncoding::Linear8 : texture.encoding);
    info.wrap_s = uint8_t(texture.wrap_s);
    info.wrap_t = uint8_t(texture.wrap_t);
    info.channels = uint8_t(texture.channels);
    info.level_count = uint32_t(std::min<size_t>(1 + chain.levels().size(), TextureInfo::kMaxLevels));
    for (uint32_t level = 0; level < info.level_count; ++level) {
        const Texture& t = level == 0 ? texture : chain.levels()[level - 1];
        const std::vector<uint8_t> texels = rgba8(t);
        info.first_tile[level] = uint32_t(s.texture_entries.size());
        const uint32_t side = kTextureTileSide;
        for (uint32_t ty = 0; ty < (uint32_t(t.height) + side - 1) / side; ++ty)
            for (uint32_t tx = 0; tx < (uint32_t(t.width) + side - 1) / side; ++tx) {
                // Edge tiles repeat their last texel so a tile is always full.
                std::vector<uint8_t> tile(side * side * 4);
                for (uint32_t y = 0; y < side; ++y)
                    for (uint32_t x = 0; x < side; ++x) {
                        const uint32_t sx = std::min(tx * side + x, uint32_t(t.width) - 1);
                        const uint32_t sy = std::min(ty * side + y, uint32_t(t.height) - 1);
                        std::memcpy(&tile[(y * side + x) * 4], &texels[(size_t(sy) * size_t(t.width) + sx) * 4], 4);
                    }
                const StoredPage page = encode_page(std::move(tile), PageKind::TextureTile, s.options.attribute_format,
                                                    s.options.codec, s.options.zstd_level);
                s.texture_entries.push_back(s.append(page, PageKind::TextureTile));
                s.summary.texture_bytes += page.bytes.size();
            }
    }
    s.textures.push_back(info);
    return uint32_t(s.textures.size() - 1);
}

uint32_t PackWriter::add_object(const ObjectInput& object) { return write_object(object, false); }

uint32_t PackWriter::add_instanced_object(const ObjectInput& object_space) { return write_object(object_space, true); }

void PackWriter::add_instance(uint32_t object, const Affine3f& world_from_object) {
    State& s = *state_;
    s.require_open("add_instance");
    if (object >= s.object_pages.size() || !s.object_pages[object].instanced)
        throw Error("paged scene writer: object " + std::to_string(object) + " was not added as an instanced object");
    for (const auto& row : world_from_object.m)
        for (float v : row)
            if (!std::isfinite(v)) throw Error("paged scene writer: an instance transform is not finite");
    const Affine3f object_from_world = world_from_object.inverse();  // rf::Error when singular
    const State::ObjectPages& o = s.object_pages[object];
    InstanceInfo info;
    std::memcpy(info.world_from_object, world_from_object.m, sizeof(info.world_from_object));
    std::memcpy(info.object_from_world, object_from_world.m, sizeof(info.object_from_world));
    info.object = object;
    info.first_page = o.first_page;
    info.page_count = o.page_count;
    const uint32_t id = uint32_t(s.instances.size());
    if (id == kNoInstance || s.refs.size() + o.page_count >= kNoInstance)
        throw Error("paged scene writer: more than 2^32 instances or instanced pages");
    s.instances.push_back(info);
    for (uint32_t p = 0; p < o.page_count; ++p) s.refs.push_back({o.first_page + p, id});
    s.summary.instanced_triangles += o.triangles;
    ++s.summary.instances;
}

uint32_t PackWriter::write_object(const ObjectInput& object, bool instanced) {
    State& s = *state_;
    s.require_open("add_object");
    check_object(object, s.materials.size());
    const uint32_t id = s.objects;
    s.object_pages.push_back({uint32_t(s.pages.size()), 0, object.indices.size() / 3, instanced});
    if (object.indices.empty()) {
        ++s.objects;
        return id;
    }
    std::vector<uint32_t> material(object.shading.size());
    for (size_t t = 0; t < material.size(); ++t) material[t] = object.shading[t].material;
    const std::vector<QuadRef> quads = parallel::with_threads(s.options.threads, [&] {
        return pair_triangles(object.positions, object.indices, material);
    });
    const std::vector<std::vector<uint32_t>> page_quads =
        partition_into_pages(object.positions, quads, s.options.quads_per_page);
    const Vec3f step = lattice_steps(object.positions, quads, page_quads);

    struct Ready {
        BuiltPage page;
        PageNode root;
        StoredPage geometry;
        std::vector<StoredPage> attributes;
    };
    std::vector<Ready> ready(page_quads.size());
    const uint32_t attribute_page = s.options.attribute_page_bytes;
    parallel::with_threads(s.options.threads, [&] {
        parallel::for_each_index(size_t(0), page_quads.size(), [&](size_t p) {
            Ready& r = ready[p];
            const PackWriterOptions& o = s.options;
            r.page = build_page(object.positions, object.shading, quads, page_quads[p], step);
            std::memcpy(&r.root, r.page.geometry.data() + sizeof(GeometryPageHeader), sizeof(PageNode));
            r.geometry = encode_page(std::move(r.page.geometry), PageKind::Geometry, o.attribute_format, o.codec,
                                     o.zstd_level);
            AttributePages cut = cut_attribute_pages(r.page.shading, o.attribute_format, attribute_page);
            r.page.info.attribute_triangles = uint16_t(cut.triangles_per_page);
            for (std::vector<uint8_t>& bytes : cut.pages)
                r.attributes.push_back(
                    encode_page(std::move(bytes), PageKind::Attributes, o.attribute_format, o.codec, o.zstd_level));
            r.page.shading = {};
        });
    });
    for (Ready& r : ready) {
        PageInfo info = r.page.info;
        info.object = id;
        info.instanced = instanced ? 1 : 0;
        if (!instanced) s.refs.push_back({uint32_t(s.pages.size()), kNoInstance});
        info.first_attribute_page = uint32_t(s.attribute_entries.size());
        s.geometry_entries.push_back(s.append(r.geometry, PageKind::Geometry));
        s.summary.geometry_bytes += r.geometry.bytes.size();
        for (const StoredPage& a : r.attributes) {
            s.attribute_entries.push_back(s.append(a, PageKind::Attributes));
            s.summary.attribute_bytes += a.bytes.size();
        }
        s.pages.push_back(info);
        s.page_roots.push_back(r.root);
        s.summary.max_quantisation_error = std::max(s.summary.max_quantisation_error, r.page.max_error);
    }
    if (s.geometry_entries.size() > (uint64_t(1) << 32) / kTrianglesPerPageSlot)
        throw Error("paged scene writer: more than " + std::to_string((uint64_t(1) << 32) / kTrianglesPerPageSlot) +
                    " geometry pages (about 4 billion triangles) do not fit 32-bit primitive ids");
    s.summary.triangles += object.indices.size() / 3;
    s.summary.quads += quads.size();
    for (const QuadRef& q : quads) s.summary.paired_triangles += q.second != QuadRef::kNoTriangle ? 2 : 0;
    s.object_pages.back().page_count = uint32_t(s.pages.size()) - s.object_pages.back().first_page;
    ++s.objects;
    return id;
}

PackSummary PackWriter::finish(const ProgressCallback& progress) {
    State& s = *state_;
    s.require_open("finish");
    if (progress) progress(0.0);
    if (s.materials.empty()) s.materials.push_back(ShadingMaterial::from(Material{}));
    ResidentHeader& r = s.resident;
    // The references' world boxes (an instanced page's object-space bounds
    // through its instance), then the chosen top level over them; the
    // other's arrays stay empty (the grid: one empty cell).
    std::vector<Box3f> boxes(s.refs.size());
    for (size_t i = 0; i < s.refs.size(); ++i) {
        const TopRef& ref = s.refs[i];
        const Box3f& b = s.pages[ref.page].bounds;
        if (ref.instance == kNoInstance) {
            boxes[i] = b;
            continue;
        }
        Affine3f m;
        std::memcpy(m.m, s.instances[ref.instance].world_from_object, sizeof(m.m));
        boxes[i] = m.transform_box(b);
    }
    TopGrid grid;
    WideTree top;
    parallel::with_threads(s.options.threads, [&] {
        if (s.options.top_level == TopLevel::Grid) {
            grid = build_top_grid(boxes, s.options.grid_resolution);
            return;
        }
        grid = build_top_grid({}, 1);
        top = build_wide_tree(boxes);
        for (const Box3f& b : boxes) grid.scene_bounds.extend(b);
        if (!boxes.empty()) grid.grid_bounds = grid.scene_bounds;
    });
    std::vector<TopRef> refs = s.refs;
    if (!top.nodes.empty())  // in the top BVH's leaf order
        for (size_t k = 0; k < refs.size(); ++k) refs[k] = s.refs[top.items[k]];
    if (progress) progress(0.8);
    r.top_level = s.options.top_level;
    r.top_node_count = uint32_t(top.nodes.size());
    r.top_ref_count = uint32_t(refs.size());
    r.instance_count = uint32_t(s.instances.size());
    r.instanced_triangles[0] = uint32_t(s.summary.instanced_triangles);
    r.instanced_triangles[1] = uint32_t(s.summary.instanced_triangles >> 32);
    r.bounds = grid.scene_bounds;
    r.grid_bounds = grid.grid_bounds;
    for (int a = 0; a < 3; ++a) r.grid_res[a] = grid.resolution[a];
    r.middle_node_count = uint32_t(grid.middle_nodes.size());
    r.material_count = uint32_t(s.materials.size());
    r.light_count = uint32_t(s.lights.size());
    r.texture_count = uint32_t(s.textures.size());
    r.object_count = s.objects;

    std::vector<uint8_t> resident;
    const auto put = [&](const void* data, size_t bytes) {
        const size_t at = resident.size();
        resident.resize(round16(at + bytes), 0);
        if (bytes) std::memcpy(resident.data() + at, data, bytes);
    };
    put(&r, sizeof(r));
    put(s.pages.data(), s.pages.size() * sizeof(PageInfo));
    put(s.page_roots.data(), s.page_roots.size() * sizeof(PageNode));
    put(grid.cell_roots.data(), grid.cell_roots.size() * sizeof(uint32_t));
    put(grid.middle_nodes.data(), grid.middle_nodes.size() * sizeof(BvhNode));
    put(top.nodes.data(), top.nodes.size() * sizeof(PageNode));
    put(refs.data(), refs.size() * sizeof(TopRef));
    put(s.instances.data(), s.instances.size() * sizeof(InstanceInfo));
    put(s.materials.data(), s.materials.size() * sizeof(ShadingMaterial));
    put(s.lights.data(), s.lights.size() * sizeof(Light));
    put(s.textures.data(), s.textures.size() * sizeof(TextureInfo));

    FileHeader h;
    std::memcpy(h.magic, kMagic, sizeof(kMagic));
    h.resident_offset = s.end;
    h.resident_bytes = resident.size();
    h.resident_checksum = crc32c(resident.data(), resident.size());
    s.write_at(resident.data(), resident.size(), s.end);
    s.end += resident.size();

    std::vector<PageEntry> directory = s.geometry_entries;
    directory.insert(directory.end(), s.attribute_entries.begin(), s.attribute_entries.end());
    directory.insert(directory.end(), s.texture_entries.begin(), s.texture_entries.end());
    h.directory_offset = s.end;
    h.page_count = directory.size();
    h.directory_checksum = crc32c(directory.data(), directory.size() * sizeof(PageEntry));
    s.write_at(directory.data(), directory.size() * sizeof(PageEntry), s.end);
    s.end += directory.size() * sizeof(PageEntry);

    h.triangle_count = s.summary.triangles;
    h.quad_count = s.summary.quads;
    h.file_bytes = s.end;
    h.geometry_pages = uint32_t(s.geometry_entries.size());
    h.attribute_pages = uint32_t(s.attribute_entries.size());
    h.texture_pages = uint32_t(s.texture_entries.size());
    h.header_checksum = crc32c(&h, offsetof(FileHeader, header_checksum));
    s.write_at(&h, sizeof(h), 0);
    if (::fsync(s.fd) != 0 && errno != EINVAL) throw file_error(s.path, 0, std::string("cannot sync: ") + std::strerror(errno));
    ::close(s.fd);
    s.fd = -1;
    s.finished = true;

    PackSummary& out = s.summary;
    out.geometry_pages = h.geometry_pages;
    out.attribute_pages = h.attribute_pages;
    out.texture_pages = h.texture_pages;
    out.middle_nodes = r.middle_node_count;
    out.top_nodes = r.top_node_count;
    out.resident_bytes = resident.size();
    out.file_bytes = s.end;
    if (progress) progress(1.0);
    return out;
}

const PackSummary& PackWriter::summary() const { return state_->summary; }

}  // namespace rf::pack
