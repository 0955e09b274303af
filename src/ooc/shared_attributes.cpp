#include "ooc/shared_attributes.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <unordered_map>

#include "rayforge/core/error.h"

namespace rf::pack {

namespace {

size_t align4(size_t n) { return (n + 3) & ~size_t(3); }

// The geometric normal keeps 12 bits of each 16-bit octahedral half
// (rounded to a multiple of 16: within 0.06 degrees; the page's 16-bit
// quantised vertices already turn a triangle by about that much), so that
// it compresses.
uint32_t round_geometric_normal(uint32_t code) {
    const auto half = [](uint32_t c) { return std::min<uint32_t>((c + 8u) & ~15u, 65520u); };
    return half(code & 0xFFFFu) | half(code >> 16) << 16;
}

// The bytes a shared vertex is compared by (normal and uv bits).
struct VertexKey {
    uint32_t normal, u, v;
    bool operator==(const VertexKey&) const = default;
};
struct VertexKeyHash {
    size_t operator()(const VertexKey& k) const {
        uint64_t h = (uint64_t(k.normal) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(k.u) << 32 | k.v);
        return size_t(h ^ (h >> 29));
    }
};

VertexKey key_of(const ShadingTriangle& t, int corner) {
    VertexKey k{t.normals[corner], 0, 0};
    std::memcpy(&k.u, &t.uv[corner].x, 4);
    std::memcpy(&k.v, &t.uv[corner].y, 4);
    return k;
}

// A run's distinct vertices and materials, in first-use order.
struct SharedRun {
    SharedPageHeader header;
    std::vector<VertexKey> vertices;
    std::vector<uint16_t> corners;
    std::vector<uint32_t> materials;
    std::vector<uint16_t> slots;
};

SharedRun index_run(std::span<const ShadingTriangle> triangles) {
    if (triangles.size() > 0xFFFF) throw Error("shared attribute page: more than 65535 triangles");
    SharedRun run;
    std::unordered_map<VertexKey, uint16_t, VertexKeyHash> vertex_of;
    std::unordered_map<uint32_t, uint16_t> slot_of;
    run.corners.reserve(3 * triangles.size());
    run.slots.reserve(triangles.size());
    for (const ShadingTriangle& t : triangles) {
        for (int c = 0; c < 3; ++c) {
            const VertexKey k = key_of(t, c);
            auto [it, added] = vertex_of.try_emplace(k, uint16_t(run.vertices.size()));
            if (added) {
                if (run.vertices.size() == 0xFFFF) throw Error("shared attribute page: more than 65535 vertices");
                run.vertices.push_back(k);
            }
            run.corners.push_back(it->second);
        }
        auto [it, added] = slot_of.try_emplace(t.material, uint16_t(run.materials.size()));
        if (added) run.materials.push_back(t.material);
        run.slots.push_back(it->second);
        if (t.flags & kHasTangent) run.header.has_tangents = 1;
    }
    run.header.triangle_count = uint16_t(triangles.size());
    run.header.vertex_count = uint16_t(run.vertices.size());
    run.header.material_count = uint16_t(run.materials.size());
    return run;
}

}  // namespace

SharedPageLayout shared_page_layout(const SharedPageHeader& h) {
    SharedPageLayout l;
    l.materials = sizeof(SharedPageHeader);
    l.vertices = l.materials + 4 * size_t(h.material_count);
    l.triangles = l.vertices + sizeof(SharedVertex) * h.vertex_count;
    l.corners = l.triangles + sizeof(SharedTriangle) * h.triangle_count;
    l.tangents = l.corners + align4(6 * size_t(h.triangle_count));
    l.bytes = l.tangents + (h.has_tangents ? 4 * size_t(h.triangle_count) : 0);
    return l;
}

uint16_t encode_uv_area_ratio(float ratio) {
    if (!(ratio > 0.0f) || !std::isfinite(ratio)) return 0;
    const double code = std::round((std::log2(double(ratio)) + 128.0) * 256.0);
    return uint16_t(std::clamp(code, 1.0, 65535.0));
}

float decode_uv_area_ratio(uint16_t code) {
    return code == 0 ? 0.0f : float(std::exp2(double(code) / 256.0 - 128.0));
}

size_t shared_page_bytes(std::span<const ShadingTriangle> triangles) {
    const SharedRun run = index_run(triangles);
    return run.materials.size() > 256 ? SIZE_MAX : shared_page_layout(run.header).bytes;
}

std::vector<uint8_t> encode_shared_page(std::span<const ShadingTriangle> triangles) {
    const SharedRun run = index_run(triangles);
    if (run.materials.size() > 256) throw Error("shared attribute page: more than 256 materials");
    const SharedPageLayout l = shared_page_layout(run.header);
    std::vector<uint8_t> page(l.bytes, 0);
    std::memcpy(page.data(), &run.header, sizeof(run.header));
    std::memcpy(page.data() + l.materials, run.materials.data(), 4 * run.materials.size());
    for (size_t i = 0; i < run.vertices.size(); ++i) {
        SharedVertex v;
        v.normal = run.vertices[i].normal;
        std::memcpy(&v.uv[0], &run.vertices[i].u, 4);
        std::memcpy(&v.uv[1], &run.vertices[i].v, 4);
        std::memcpy(page.data() + l.vertices + i * sizeof(SharedVertex), &v, sizeof(v));
    }
    for (size_t i = 0; i < triangles.size(); ++i) {
        const ShadingTriangle& t = triangles[i];
        SharedTriangle s;
        s.geometric_normal = round_geometric_normal(encode_octahedral(t.geometric_normal));
        s.uv_area_log = encode_uv_area_ratio(t.uv_area_ratio);
        s.material_slot = uint8_t(run.slots[i]);
        s.flags = uint8_t(t.flags);
        std::memcpy(page.data() + l.triangles + i * sizeof(SharedTriangle), &s, sizeof(s));
        if (run.header.has_tangents) std::memcpy(page.data() + l.tangents + 4 * i, &t.tangent, 4);
    }
    std::memcpy(page.data() + l.corners, run.corners.data(), 2 * run.corners.size());
    return page;
}

ShadingTriangle decode_shared_record(const uint8_t* page, uint32_t triangle) {
    SharedPageHeader h;
    std::memcpy(&h, page, sizeof(h));
    const SharedPageLayout l = shared_page_layout(h);
    SharedTriangle s;
    std::memcpy(&s, page + l.triangles + size_t(triangle) * sizeof(SharedTriangle), sizeof(s));
    uint16_t corner[3];
    std::memcpy(corner, page + l.corners + 6 * size_t(triangle), 6);
    ShadingTriangle t;
    t.geometric_normal = decode_octahedral(s.geometric_normal);
    std::memcpy(&t.material, page + l.materials + 4 * size_t(s.material_slot), 4);
    for (int c = 0; c < 3; ++c) {
        SharedVertex v;
        std::memcpy(&v, page + l.vertices + size_t(corner[c]) * sizeof(SharedVertex), sizeof(v));
        t.normals[c] = v.normal;
        t.uv[c] = Vec2f{v.uv[0], v.uv[1]};
    }
    t.uv_area_ratio = decode_uv_area_ratio(s.uv_area_log);
    if (h.has_tangents) std::memcpy(&t.tangent, page + l.tangents + 4 * size_t(triangle), 4);
    t.flags = s.flags;
    return t;
}

std::string check_shared_page(std::span<const uint8_t> page, uint32_t triangle_count, uint32_t material_count) {
    if (page.size() < sizeof(SharedPageHeader)) return "a shared attribute page shorter than its header";
    SharedPageHeader h;
    std::memcpy(&h, page.data(), sizeof(h));
    if (h.triangle_count != triangle_count)
        return "a shared attribute page of " + std::to_string(h.triangle_count) + " triangles where " +
               std::to_string(triangle_count) + " belong";
    if (h.has_tangents > 1 || h.reserved != 0 || h.material_count > 256)
        return "a shared attribute page with a bad header";
    const SharedPageLayout l = shared_page_layout(h);
    if (l.bytes != page.size()) return "a shared attribute page of the wrong size";
    for (uint32_t m = 0; m < h.material_count; ++m) {
        uint32_t material;
        std::memcpy(&material, page.data() + l.materials + 4 * size_t(m), 4);
        if (material >= material_count) return "a shared attribute page names material " + std::to_string(material);
    }
    for (uint32_t i = 0; i < h.triangle_count; ++i) {
        SharedTriangle s;
        std::memcpy(&s, page.data() + l.triangles + size_t(i) * sizeof(SharedTriangle), sizeof(s));
        if (s.material_slot >= h.material_count) return "a shared attribute triangle with a bad material slot";
    }
    for (size_t c = 0; c < 3 * size_t(h.triangle_count); ++c) {
        uint16_t v;
        std::memcpy(&v, page.data() + l.corners + 2 * c, 2);
        if (v >= h.vertex_count) return "a shared attribute corner past the page's vertices";
    }
    return "";
}

}  // namespace rf::pack
