// Reading a paged scene file: the header, directory and resident section are
// read and checked once at open; pages are read on demand (pread: safe from
// many threads at once), checked against their checksum and decompressed.
// Every failure is an rf::Error naming the file and the byte offset.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "ooc/pack_format.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/light.h"
#include "render/material_eval.h"

namespace rf::pack {

class PackFile {
public:
    // Opens and validates `path` (magic, version, sizes, checksums of the
    // header, directory and resident section, every directory entry in the file).
    explicit PackFile(const std::string& path);
    ~PackFile();
    PackFile(const PackFile&) = delete;
    PackFile& operator=(const PackFile&) = delete;

    [[nodiscard]] const std::string& path() const { return path_; }
    [[nodiscard]] const FileHeader& header() const { return header_; }
    [[nodiscard]] const ResidentHeader& resident() const { return resident_; }

    [[nodiscard]] std::span<const PageEntry> directory() const { return directory_; }
    [[nodiscard]] std::span<const PageInfo> pages() const { return pages_; }
    // A copy of each geometry page's root node (equal to the page's node 0: checked when the page is read).
    [[nodiscard]] std::span<const PageNode> page_roots() const { return page_roots_; }
    [[nodiscard]] std::span<const uint32_t> cell_roots() const { return cell_roots_; }
    [[nodiscard]] std::span<const BvhNode> middle_nodes() const { return middle_nodes_; }
    // TopLevel::WideBvh: the top BVH (empty for a grid file or no pages).
    [[nodiscard]] std::span<const PageNode> top_nodes() const { return top_nodes_; }
    // What the top level reaches (in the top BVH's leaf order), and the instances.
    [[nodiscard]] std::span<const TopRef> top_refs() const { return top_refs_; }
    [[nodiscard]] std::span<const InstanceInfo> instances() const { return instances_; }
    [[nodiscard]] std::span<const ShadingMaterial> materials() const { return materials_; }
    [[nodiscard]] std::span<const Light> lights() const { return lights_; }
    [[nodiscard]] std::span<const TextureInfo> textures() const { return textures_; }

    // Directory index of the first page of each kind.
    [[nodiscard]] uint64_t first_attribute_page() const { return header_.geometry_pages; }
    [[nodiscard]] uint64_t first_texture_page() const {
        return uint64_t(header_.geometry_pages) + header_.attribute_pages;
    }
    [[nodiscard]] bool has_camera() const { return resident_.has_camera != 0; }
    [[nodiscard]] Camera camera() const;
    [[nodiscard]] Environment environment() const;

    // Reads directory page `index` into `out` (resized to its raw size),
    // verifying its checksum, decompressing it and checking its contents
    // (a geometry page's nodes and quad count, an attribute page's or a
    // tile's size); `scratch` holds the
    // stored bytes of a compressed page (pass one per thread to avoid
    // reallocations). Thread-safe. Returns the bytes read from the file.
    size_t read_page(uint64_t index, std::vector<uint8_t>& out, std::vector<uint8_t>& scratch) const;
    // The same into a caller's buffer of at least raw_bytes (a cache slot).
    size_t read_page(uint64_t index, std::span<uint8_t> out, std::vector<uint8_t>& scratch) const;
    // read_page in two steps, for readers that do the I/O themselves
    // (uring_reader.h): read entry(index).stored_bytes at entry(index).offset
    // of fd(), into `out` itself for a raw page (Codec::None), then
    // finish_page: the checksum, the codec into `out`, the content checks.
    [[nodiscard]] const PageEntry& entry(uint64_t index) const;
    [[nodiscard]] int fd() const { return fd_; }
    void finish_page(uint64_t index, std::span<const uint8_t> stored, std::span<uint8_t> out) const;

    // Asks the operating system to drop the file's pages from its page
    // cache (posix_fadvise DONTNEED): later reads come from the disk (cold
    // measurements). Best effort: ignored where refused.
    void drop_os_cache() const;

    // Bytes of the resident section held in memory.
    [[nodiscard]] size_t resident_memory_bytes() const;

private:
    void open_checked();
    void read_directory(uint64_t size);
    void read_resident(uint64_t size);
    void validate_resident() const;
    void validate_instances() const;
    void validate_materials() const;
    void check_page_contents(uint64_t index, std::span<const uint8_t> raw) const;
    [[nodiscard]] uint32_t attribute_page_triangles(uint32_t attribute_page) const;

    std::string path_;
    int fd_ = -1;
    FileHeader header_{};
    ResidentHeader resident_{};
    std::vector<PageEntry> directory_;
    std::vector<PageInfo> pages_;
    std::vector<PageNode> page_roots_;
    std::vector<uint32_t> cell_roots_;
    std::vector<BvhNode> middle_nodes_;
    std::vector<PageNode> top_nodes_;
    std::vector<TopRef> top_refs_;
    std::vector<InstanceInfo> instances_;
    std::vector<ShadingMaterial> materials_;
    std::vector<Light> lights_;
    std::vector<TextureInfo> textures_;
};

// A geometry page's parts, viewed in its raw bytes.
struct GeometryPageView {
    const PageNode* nodes = nullptr;
    const Quad* quads = nullptr;
    uint32_t node_count = 0;
    uint32_t quad_count = 0;
};
// "" when nodes[0, node_count) form a wide tree view_geometry_page accepts
// (well-formed slots, leaf items below item_count, children after their
// parent, one parent each, at most kCwbvhMaxDepth deep), else what is wrong.
std::string check_wide_tree(const PageNode* nodes, uint32_t node_count, uint32_t item_count);

// Views `bytes` as a geometry page; rf::Error (naming `what`) when its sizes
// disagree or a node points outside the page or backwards (so traversal of
// a checked page always ends).
GeometryPageView view_geometry_page(std::span<const uint8_t> bytes, const std::string& what);

}  // namespace rf::pack
