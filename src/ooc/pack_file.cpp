// Reading a paged scene file: everything always resident is read and checked
// at open, so a page read later can only fail on its own bytes.
#include "ooc/pack_file.h"

#include <bit>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "ooc/page_codec.h"
#include "ooc/shared_attributes.h"
#include "rayforge/core/error.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/memory_budget.h"

#if defined(__SSE4_2__)
#include <nmmintrin.h>
#endif

namespace rf::pack {

namespace {

// The largest page the reader accepts (a geometry page is about 120 KB,
// attribute and texture pages a few KB): a corrupted size cannot ask for gigabytes.
constexpr uint32_t kMaxPageBytes = 16u << 20;

uint32_t crc32c_table_step(uint32_t crc, const uint8_t* p, size_t n) {
    static const auto table = [] {
        std::array<uint32_t, 256> t{};
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
            t[i] = c;
        }
        return t;
    }();
    for (size_t i = 0; i < n; ++i) crc = table[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
    return crc;
}

// Reads exactly `bytes` at `offset`; false on a short read.
bool read_at(int fd, void* out, size_t bytes, uint64_t offset) {
    auto* p = static_cast<uint8_t*>(out);
    while (bytes > 0) {
        const ssize_t got = ::pread(fd, p, bytes, off_t(offset));
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) return false;
        p += got;
        bytes -= size_t(got);
        offset += uint64_t(got);
    }
    return true;
}

bool finite_box(const Box3f& b) {
    return std::isfinite(b.lo.x) && std::isfinite(b.lo.y) && std::isfinite(b.lo.z) && std::isfinite(b.hi.x) &&
           std::isfinite(b.hi.y) && std::isfinite(b.hi.z) && b.lo.x <= b.hi.x && b.lo.y <= b.hi.y && b.lo.z <= b.hi.z;
}

bool finite_vec(Vec3f v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

size_t round16(size_t n) { return (n + 15) & ~size_t(15); }

// The resident section's arrays, read in order with bounds checks.
class SectionReader {
public:
    SectionReader(const std::vector<uint8_t>& bytes, const std::string& path, uint64_t base)
        : bytes_(bytes), path_(path), base_(base) {}

    template <class T>
    void read_one(T& out, const char* what) {
        check(sizeof(T), what);
        std::memcpy(&out, bytes_.data() + at_, sizeof(T));
        at_ = round16(at_ + sizeof(T));
    }
    template <class T>
    void read_array(std::vector<T>& out, uint64_t count, const char* what) {
        if (count > (bytes_.size() - std::min(at_, bytes_.size())) / sizeof(T) + 1)
            throw file_byte_error(path_, base_ + at_, std::string(what) + ": count " + std::to_string(count) +
                                                          " does not fit in the resident section");
        check(size_t(count) * sizeof(T), what);
        out.resize(size_t(count));
        if (count) std::memcpy(out.data(), bytes_.data() + at_, size_t(count) * sizeof(T));
        at_ = round16(at_ + size_t(count) * sizeof(T));
    }

private:
    void check(size_t n, const char* what) const {
        if (at_ > bytes_.size() || n > bytes_.size() - at_)
            throw file_byte_error(path_, base_ + at_, std::string("resident section ends inside ") + what);
    }
    const std::vector<uint8_t>& bytes_;
    const std::string& path_;
    uint64_t base_;
    size_t at_ = 0;
};

}  // namespace

uint32_t crc32c(const void* data, size_t bytes, uint32_t seed) {
    const auto* p = static_cast<const uint8_t*>(data);
    uint32_t crc = ~seed;
#if defined(__SSE4_2__)
    uint64_t c = crc;
    for (; bytes >= 8; bytes -= 8, p += 8) {
        uint64_t word;
        std::memcpy(&word, p, 8);
        c = _mm_crc32_u64(c, word);
    }
    crc = uint32_t(c);
#endif
    crc = crc32c_table_step(crc, p, bytes);
    return ~crc;
}

PackFile::PackFile(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw file_error(path, 0, std::string("cannot open: ") + std::strerror(errno));
    try {
        open_checked();
    } catch (...) {
        ::close(fd_);
        fd_ = -1;
        throw;
    }
}

PackFile::~PackFile() {
    if (fd_ >= 0) ::close(fd_);
}

void PackFile::open_checked() {
    struct stat st{};
    if (::fstat(fd_, &st) != 0) throw file_error(path_, 0, std::string("cannot stat: ") + std::strerror(errno));
    const uint64_t size = uint64_t(st.st_size);
    if (size < sizeof(FileHeader) || !read_at(fd_, &header_, sizeof(header_), 0))
        throw file_byte_error(path_, 0, "not a paged scene file (shorter than its header)");
    if (std::memcmp(header_.magic, kMagic, sizeof(kMagic)) != 0)
        throw file_byte_error(path_, 0, "not a paged scene file (bad magic)");
    if (header_.version != kVersion)
        throw file_byte_error(path_, 8, "unsupported paged scene version " + std::to_string(header_.version) +
                                            " (this rayforge reads version " + std::to_string(kVersion) +
                                            (header_.version < kVersion ? "; convert the scene again" : "") + ")");
    if (header_.header_bytes != sizeof(FileHeader) ||
        crc32c(&header_, offsetof(FileHeader, header_checksum)) != header_.header_checksum)
        throw file_byte_error(path_, 0, "header checksum mismatch (corrupted file)");
    if (header_.file_bytes != size)
        throw file_byte_error(path_, size, "file is truncated or padded: " + std::to_string(size) +
                                               " bytes, the header says " + std::to_string(header_.file_bytes));
    read_directory(size);
    read_resident(size);
}

void PackFile::read_directory(uint64_t size) {
    const FileHeader& h = header_;
    const uint64_t kinds = uint64_t(h.geometry_pages) + h.attribute_pages + h.texture_pages;
    if (h.page_count != kinds) throw file_byte_error(path_, 0, "page counts disagree in the header");
    if (uint64_t(h.geometry_pages) > (uint64_t(1) << 32) / kTrianglesPerPageSlot)
        throw file_byte_error(path_, 0, "more geometry pages than 32-bit primitive ids can name");
    if (h.directory_offset > size || h.page_count > (size - h.directory_offset) / sizeof(PageEntry))
        throw file_byte_error(path_, h.directory_offset, "page directory lies outside the file");
    budgeted_resize(directory_, size_t(h.page_count), "paged scene directory");
    if (!read_at(fd_, directory_.data(), directory_.size() * sizeof(PageEntry), h.directory_offset))
        throw file_byte_error(path_, h.directory_offset, "cannot read the page directory");
    if (crc32c(directory_.data(), directory_.size() * sizeof(PageEntry)) != h.directory_checksum)
        throw file_byte_error(path_, h.directory_offset, "page directory checksum mismatch (corrupted file)");
    for (uint64_t i = 0; i < directory_.size(); ++i) {
        const PageEntry& e = directory_[i];
        const PageKind want = i < h.geometry_pages                      ? PageKind::Geometry
                              : i < first_texture_page()                ? PageKind::Attributes
                                                                        : PageKind::TextureTile;
        const uint64_t at = h.directory_offset + i * sizeof(PageEntry);
        const bool codec_ok = e.codec == Codec::None || e.codec == Codec::Zstd ||
                              (e.codec == Codec::Meshopt && e.kind != PageKind::TextureTile);
        if (e.kind != want || !codec_ok)
            throw file_byte_error(path_, at, "page " + std::to_string(i) + ": bad kind or codec");
        if (e.offset > size || e.stored_bytes > size - e.offset || e.raw_bytes > kMaxPageBytes ||
            e.stored_bytes == 0 || (e.codec == Codec::None && e.stored_bytes != e.raw_bytes))
            throw file_byte_error(path_, at, "page " + std::to_string(i) + ": bad offset or size");
    }
}

void PackFile::read_resident(uint64_t size) {
    const FileHeader& h = header_;
    if (h.resident_offset > size || h.resident_bytes > size - h.resident_offset || h.resident_bytes < sizeof(ResidentHeader))
        throw file_byte_error(path_, h.resident_offset, "resident section lies outside the file");
    std::vector<uint8_t> bytes;
    budgeted_resize(bytes, size_t(h.resident_bytes), "paged scene resident section");
    if (!read_at(fd_, bytes.data(), bytes.size(), h.resident_offset))
        throw file_byte_error(path_, h.resident_offset, "cannot read the resident section");
    if (crc32c(bytes.data(), bytes.size()) != h.resident_checksum)
        throw file_byte_error(path_, h.resident_offset, "resident section checksum mismatch (corrupted file)");
    SectionReader in(bytes, path_, h.resident_offset);
    in.read_one(resident_, "the resident header");
    const ResidentHeader& r = resident_;
    for (int a = 0; a < 3; ++a)
        if (r.grid_res[a] < 1 || r.grid_res[a] > kMaxGridResolution)
            throw file_byte_error(path_, h.resident_offset, "bad top-grid resolution");
    if (r.top_level != TopLevel::WideBvh && r.top_level != TopLevel::Grid)
        throw file_byte_error(path_, h.resident_offset, "bad top level");
    if ((r.top_level == TopLevel::WideBvh) != (r.top_node_count > 0 || r.top_ref_count == 0) ||
        r.top_node_count > 2 * uint64_t(r.top_ref_count))
        throw file_byte_error(path_, h.resident_offset, "top BVH node count disagrees with the top level");
    if (r.attribute_format != AttributeFormat::Full && r.attribute_format != AttributeFormat::Compact &&
        r.attribute_format != AttributeFormat::Shared)
        throw file_byte_error(path_, h.resident_offset, "bad attribute format");
    if (r.attribute_page_bytes < 1024 || r.attribute_page_bytes > (1u << 20) ||
        (r.attribute_page_bytes & (r.attribute_page_bytes - 1)) != 0)
        throw file_byte_error(path_, h.resident_offset, "bad attribute page size");
    if (h.geometry_pages > 0 && (!finite_box(r.bounds) || !finite_box(r.grid_bounds)))
        throw file_byte_error(path_, h.resident_offset, "non-finite scene bounds");
    const uint64_t cells = uint64_t(r.grid_res[0]) * uint64_t(r.grid_res[1]) * uint64_t(r.grid_res[2]);
    in.read_array(pages_, h.geometry_pages, "page bounds");
    in.read_array(page_roots_, h.geometry_pages, "page roots");
    in.read_array(cell_roots_, cells, "top-grid cells");
    in.read_array(middle_nodes_, r.middle_node_count, "middle BVH nodes");
    in.read_array(top_nodes_, r.top_node_count, "top BVH nodes");
    in.read_array(top_refs_, r.top_ref_count, "top references");
    in.read_array(instances_, r.instance_count, "instances");
    in.read_array(materials_, r.material_count, "materials");
    in.read_array(lights_, r.light_count, "lights");
    in.read_array(textures_, r.texture_count, "textures");
    validate_resident();
}

namespace {

// A page's decode scale: per axis a power of two whose reciprocal is a
// normal float too (the traversal divides by multiplying with it).
bool power_of_two_scale(const Vec3f& scale) {
    for (int a = 0; a < 3; ++a) {
        const uint32_t bits = float_to_bits(scale[a]);
        const uint32_t exponent = (bits >> 23) & 0xFFu;
        if ((bits & 0x807FFFFFu) != 0 || exponent < 1 || exponent > 253) return false;
    }
    return true;
}

}  // namespace

// The references and instances: every reference to a page that exists,
// world-space pages directly and object-space ones through an instance of
// their object; finite transforms; each instance's page range its object's.
void PackFile::validate_instances() const {
    const uint64_t at = header_.resident_offset;
    for (size_t i = 0; i < instances_.size(); ++i) {
        const InstanceInfo& inst = instances_[i];
        bool finite = true;
        for (int k = 0; k < 12; ++k)
            finite = finite && std::isfinite(inst.world_from_object[k]) && std::isfinite(inst.object_from_world[k]);
        if (!finite || uint64_t(inst.first_page) + inst.page_count > pages_.size())
            throw file_byte_error(path_, at, "instance " + std::to_string(i) + ": bad transform or page range");
        for (uint32_t p = inst.first_page; p < inst.first_page + inst.page_count; ++p)
            if (!pages_[p].instanced || pages_[p].object != inst.object)
                throw file_byte_error(path_, at, "instance " + std::to_string(i) + ": its pages are not its object's");
    }
    for (size_t i = 0; i < top_refs_.size(); ++i) {
        const TopRef& ref = top_refs_[i];
        const bool ok = ref.page < pages_.size() &&
                        (ref.instance == kNoInstance
                             ? pages_[ref.page].instanced == 0
                             : ref.instance < instances_.size() && pages_[ref.page].instanced == 1 &&
                                   ref.page - instances_[ref.instance].first_page < instances_[ref.instance].page_count);
        if (!ok) throw file_byte_error(path_, at, "top reference " + std::to_string(i) + " is malformed");
    }
}

void PackFile::validate_resident() const {
    const uint64_t at = header_.resident_offset;
    const uint32_t record = attribute_record_bytes(resident_.attribute_format);
    uint64_t next_attribute_page = 0;  // the writer lays each page's attribute pages after the previous one's
    for (size_t i = 0; i < pages_.size(); ++i) {
        const PageInfo& p = pages_[i];
        // Records of a fixed size fill their pages; shared runs are whatever fits (at least one triangle).
        const bool run_ok = record != 0 ? p.attribute_triangles == resident_.attribute_page_bytes / record
                                        : p.attribute_triangles >= 1 && p.attribute_triangles <= 2 * kQuadsPerPage;
        if (!run_ok) throw file_byte_error(path_, at, "page " + std::to_string(i) + ": bad attribute run length");
        const uint64_t attribute_pages = (2ull * p.quad_count + p.attribute_triangles - 1) / p.attribute_triangles;
        if (p.first_attribute_page != next_attribute_page)
            throw file_byte_error(path_, at, "page " + std::to_string(i) + ": its attribute pages are out of order");
        next_attribute_page += attribute_pages;
        if (!finite_box(p.bounds) || !finite_vec(p.offset) || !power_of_two_scale(p.scale) || p.instanced > 1 ||
            p.quad_count == 0 ||
            p.quad_count > kQuadsPerPage || uint64_t(p.first_attribute_page) + attribute_pages > header_.attribute_pages)
            throw file_byte_error(path_, at, "page " + std::to_string(i) + ": bad bounds, size or attribute range");
    }
    const uint32_t n = uint32_t(middle_nodes_.size());
    for (uint32_t root : cell_roots_)
        if (root != kEmptyCell && root >= n) throw file_byte_error(path_, at, "a top-grid cell points past the middle BVHs");
    for (uint32_t i = 0; i < n; ++i) {
        const BvhNode& node = middle_nodes_[i];
        const bool bad = node.is_leaf() ? (node.count != 1 || node.first >= top_refs_.size())
                                        : (node.first <= i || node.first >= n - 1);
        if (bad || !finite_box(node.bounds))
            throw file_byte_error(path_, at, "middle BVH node " + std::to_string(i) + " is malformed");
    }
    validate_instances();
    if (!top_nodes_.empty()) {
        const std::string problem = check_wide_tree(top_nodes_.data(), uint32_t(top_nodes_.size()), uint32_t(top_refs_.size()));
        if (!problem.empty()) throw file_byte_error(path_, at, "top BVH " + problem);
    }
    validate_materials();
    for (const TextureInfo& t : textures_) {
        if (t.width == 0 || t.height == 0 || t.width > 65536 || t.height > 65536 || t.level_count == 0 ||
            t.level_count > uint32_t(TextureInfo::kMaxLevels))
            throw file_byte_error(path_, at, "a texture has bad dimensions");
        for (uint32_t level = 0; level < t.level_count; ++level) {
            const uint32_t w = std::max(1u, t.width >> level), h = std::max(1u, t.height >> level);
            const uint64_t tiles = uint64_t((w + kTextureTileSide - 1) / kTextureTileSide) *
                                   ((h + kTextureTileSide - 1) / kTextureTileSide);
            if (uint64_t(t.first_tile[level]) + tiles > header_.texture_pages)
                throw file_byte_error(path_, at, "a texture's tiles lie past the texture pages");
        }
    }
}

// Materials are read as they lie in the file: their enum and bool bytes must
// hold valid values, and they must be opaque (the format's surfaces are).
void PackFile::validate_materials() const {
    const uint64_t at = header_.resident_offset;
    if (materials_.empty()) throw file_byte_error(path_, at, "the file has no material");
    const auto texture_ok = [&](int32_t id) { return id == -1 || (id >= 0 && uint32_t(id) < textures_.size()); };
    for (const ShadingMaterial& m : materials_) {
        uint8_t alpha_mode = 0, two_sided = 0;
        std::memcpy(&alpha_mode, &m.alpha_mode, 1);
        std::memcpy(&two_sided, &m.two_sided_emission, 1);
        static_assert(sizeof(m.alpha_mode) == 1 && sizeof(m.two_sided_emission) == 1);
        if (alpha_mode != uint8_t(AlphaMode::Opaque) || two_sided > 1)
            throw file_byte_error(path_, at, "a material is not opaque or has bad flags (paged surfaces are opaque)");
        if (!texture_ok(m.base_color_texture) || !texture_ok(m.metallic_roughness_texture) ||
            !texture_ok(m.normal_texture) || !texture_ok(m.emission_texture))
            throw file_byte_error(path_, at, "a material names a texture the file does not have");
    }
}

Camera PackFile::camera() const {
    const float* c = resident_.camera;
    Camera camera;
    camera.eye = {c[0], c[1], c[2]};
    camera.target = {c[3], c[4], c[5]};
    camera.up = {c[6], c[7], c[8]};
    camera.vfov_degrees = c[9];
    camera.aperture_radius = resident_.camera_lens[0];
    camera.focus_distance = resident_.camera_lens[1];
    return camera;
}

Environment PackFile::environment() const {
    const float* e = resident_.environment;
    Environment env;
    env.color = {e[0], e[1], e[2]};
    env.strength = e[3];
    env.rotation_radians = e[4];
    return env;
}

size_t PackFile::read_page(uint64_t index, std::vector<uint8_t>& out, std::vector<uint8_t>& scratch) const {
    if (index >= directory_.size()) throw Error(path_ + ": page " + std::to_string(index) + " does not exist");
    out.resize(directory_[size_t(index)].raw_bytes);
    return read_page(index, std::span<uint8_t>(out), scratch);
}

const PageEntry& PackFile::entry(uint64_t index) const {
    if (index >= directory_.size()) throw Error(path_ + ": page " + std::to_string(index) + " does not exist");
    return directory_[size_t(index)];
}

size_t PackFile::read_page(uint64_t index, std::span<uint8_t> out, std::vector<uint8_t>& scratch) const {
    const PageEntry& e = entry(index);
    if (out.size() < e.raw_bytes)
        throw Error(path_ + ": page " + std::to_string(index) + " is larger than its cache slot");
    uint8_t* stored = out.data();
    if (e.codec != Codec::None) {
        scratch.resize(e.stored_bytes);
        stored = scratch.data();
    }
    if (!read_at(fd_, stored, e.stored_bytes, e.offset))
        throw file_byte_error(path_, e.offset, "cannot read page " + std::to_string(index) + ": " +
                                                   (errno ? std::strerror(errno) : "short read"));
    finish_page(index, {stored, e.stored_bytes}, out);
    return e.stored_bytes;
}

void PackFile::finish_page(uint64_t index, std::span<const uint8_t> stored, std::span<uint8_t> out) const {
    const PageEntry& e = entry(index);
    if (out.size() < e.raw_bytes) throw Error(path_ + ": page " + std::to_string(index) + " is larger than its cache slot");
    if (stored.size() != e.stored_bytes)
        throw Error(path_ + ": page " + std::to_string(index) + ": " + std::to_string(stored.size()) +
                    " stored bytes given, the directory says " + std::to_string(e.stored_bytes));
    if (crc32c(stored.data(), stored.size()) != e.checksum)
        throw file_byte_error(path_, e.offset, "page " + std::to_string(index) + " checksum mismatch (corrupted file)");
    if (e.codec != Codec::None &&
        !decode_page(stored, e.codec, e.kind, resident_.attribute_format, out.first(e.raw_bytes)))
        throw file_byte_error(path_, e.offset, "page " + std::to_string(index) + " does not decompress");
    check_page_contents(index, out.first(e.raw_bytes));
}

// A page whose checksum is right may still have been written wrong (or
// crafted): what the traversal and the shading read from it is checked here,
// once per read, so the per-ray code can trust cached pages.
void PackFile::check_page_contents(uint64_t index, std::span<const uint8_t> raw) const {
    const std::string what = path_ + ": page " + std::to_string(index);
    if (index < header_.geometry_pages) {
        const GeometryPageView g = view_geometry_page(raw, what);
        // Rays test the resident copy of the root, then walk the page's nodes from its result.
        if (std::memcmp(g.nodes, &page_roots_[size_t(index)], sizeof(PageNode)) != 0)
            throw Error(what + ": its root node differs from the resident copy");
        if (g.quad_count != pages_[size_t(index)].quad_count)
            throw Error(what + ": holds " + std::to_string(g.quad_count) + " quads, its bounds record says " +
                        std::to_string(pages_[size_t(index)].quad_count));
        return;
    }
    if (index < first_texture_page()) {
        // (A page no geometry page owns is never read by shading: not checked.)
        const uint32_t triangles = attribute_page_triangles(uint32_t(index - first_attribute_page()));
        if (triangles == 0) return;
        const uint32_t record = attribute_record_bytes(resident_.attribute_format);
        if (record != 0) {
            if (raw.size() != size_t(triangles) * record) throw Error(what + ": an attribute page of the wrong size");
            return;
        }
        const std::string problem = check_shared_page(raw, triangles, uint32_t(materials_.size()));
        if (!problem.empty()) throw Error(what + ": " + problem);
        return;
    }
    if (raw.size() != size_t(kTextureTileSide) * kTextureTileSide * 4) throw Error(what + ": a texture tile of the wrong size");
}

// Attribute page `a` holds triangles of the geometry page whose range
// contains it: full runs, and the rest of its 2 * quad_count triangles in
// the last.
uint32_t PackFile::attribute_page_triangles(uint32_t a) const {
    const auto owner = std::upper_bound(pages_.begin(), pages_.end(), a, [](uint32_t x, const PageInfo& p) {
        return x < p.first_attribute_page;
    });
    if (owner == pages_.begin()) return 0;
    const PageInfo& p = *(owner - 1);
    const uint64_t triangles = 2ull * p.quad_count;
    const uint64_t first = uint64_t(a - p.first_attribute_page) * p.attribute_triangles;
    if (first >= triangles) return 0;
    return uint32_t(std::min<uint64_t>(p.attribute_triangles, triangles - first));
}

void PackFile::drop_os_cache() const {
    (void)::posix_fadvise(fd_, 0, 0, POSIX_FADV_DONTNEED);
}

size_t PackFile::resident_memory_bytes() const {
    return directory_.capacity() * sizeof(PageEntry) + pages_.capacity() * sizeof(PageInfo) +
           page_roots_.capacity() * sizeof(PageNode) +
           cell_roots_.capacity() * sizeof(uint32_t) + middle_nodes_.capacity() * sizeof(BvhNode) +
           top_nodes_.capacity() * sizeof(PageNode) + top_refs_.capacity() * sizeof(TopRef) +
           instances_.capacity() * sizeof(InstanceInfo) +
           materials_.capacity() * sizeof(ShadingMaterial) + lights_.capacity() * sizeof(Light) +
           textures_.capacity() * sizeof(TextureInfo);
}

// The structure the wide traversals rely on: every slot's meta well formed,
// leaves within the items, inner children after their parent and within the
// nodes, each node but the root referenced exactly once (a tree, so a walk
// visits each node at most once), depth at most kCwbvhMaxDepth (the
// traversal's stack).
std::string check_wide_tree(const PageNode* nodes, uint32_t node_count, uint32_t item_count) {
    std::vector<uint8_t> depth(node_count, 0);
    depth[0] = 1;
    for (uint32_t i = 0; i < node_count; ++i) {
        PageNode n;
        std::memcpy(&n, &nodes[i], sizeof(n));
        if (depth[i] == 0) return "node " + std::to_string(i) + " is not reachable from the root";
        unsigned inner_slots = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            const uint8_t meta = n.meta[s];
            if (meta == kCwbvhEmptyMeta) continue;
            if (cwbvh_meta_is_inner(meta)) {
                if (meta != cwbvh_inner_meta(s)) return "node " + std::to_string(i) + " has a malformed inner slot";
                inner_slots |= 1u << s;
                continue;
            }
            const unsigned count_bits = meta >> 5, offset = meta & 31u;
            if ((count_bits != 1 && count_bits != 3 && count_bits != 7) || offset >= 24)
                return "node " + std::to_string(i) + " has a malformed leaf slot";
            if (uint64_t(n.base_index_triangle) + offset + unsigned(std::popcount(count_bits)) > item_count)
                return "node " + std::to_string(i) + " has a leaf past its items";
        }
        if (inner_slots != n.imask) return "node " + std::to_string(i) + " has an inner mask that disagrees with its slots";
        const unsigned inner_count = unsigned(std::popcount(inner_slots));
        if (inner_count == 0) continue;
        if (n.base_index_child <= i || uint64_t(n.base_index_child) + inner_count > node_count)
            return "node " + std::to_string(i) + " has children outside the page or before it";
        if (depth[i] >= kCwbvhMaxDepth) return "node " + std::to_string(i) + " is deeper than " + std::to_string(kCwbvhMaxDepth);
        for (unsigned c = 0; c < inner_count; ++c) {
            uint8_t& d = depth[n.base_index_child + c];
            if (d != 0) return "node " + std::to_string(n.base_index_child + c) + " has two parents";
            d = uint8_t(depth[i] + 1);
        }
    }
    return "";
}

GeometryPageView view_geometry_page(std::span<const uint8_t> bytes, const std::string& what) {
    GeometryPageHeader h;
    if (bytes.size() < sizeof(h)) throw Error(what + ": geometry page shorter than its header");
    std::memcpy(&h, bytes.data(), sizeof(h));
    const uint64_t need = sizeof(h) + uint64_t(h.node_count) * sizeof(PageNode) + uint64_t(h.quad_count) * sizeof(Quad);
    if (h.quad_count == 0 || h.quad_count > kQuadsPerPage || h.node_count == 0 || h.node_count > 2 * kQuadsPerPage ||
        need > bytes.size())
        throw Error(what + ": geometry page sizes disagree with its bytes");
    const auto* nodes = reinterpret_cast<const PageNode*>(bytes.data() + sizeof(h));
    const std::string problem = check_wide_tree(nodes, h.node_count, h.quad_count);
    if (!problem.empty()) throw Error(what + ": geometry page " + problem);
    GeometryPageView v;
    v.nodes = nodes;
    v.quads = reinterpret_cast<const Quad*>(bytes.data() + sizeof(h) + size_t(h.node_count) * sizeof(PageNode));
    v.node_count = h.node_count;
    v.quad_count = h.quad_count;
    return v;
}

}  // namespace rf::pack
