#include "ooc/page_codec.h"

#include <meshoptimizer.h>
#include <zstd.h>

#include <cstring>
#include <memory>
#include <unordered_map>

#include "ooc/shared_attributes.h"

namespace rf::pack {

namespace {

// An array of fixed-size records inside a raw page (or a shared page's
// corners: a uint16 triangle list).
struct RecordArray {
    size_t offset = 0, stride = 0, count = 0;
    bool corners = false;  // a shared attribute page's corners: uint16 triangles (put_triangles)
    bool quads = false;    // a geometry page's quads: stored as their distinct vertices and 4 indices a quad
    [[nodiscard]] size_t end() const { return offset + stride * count; }
};

// The raw bytes the arrays are found from: a geometry page's header, a
// shared attribute page's header and materials; 0 when the head is too
// short to tell.
size_t prefix_bytes(PageKind kind, AttributeFormat format, std::span<const uint8_t> head) {
    if (kind == PageKind::Geometry) return sizeof(GeometryPageHeader);
    if (kind == PageKind::Attributes && format == AttributeFormat::Shared) {
        if (head.size() < sizeof(SharedPageHeader)) return sizeof(SharedPageHeader);
        SharedPageHeader h;
        std::memcpy(&h, head.data(), sizeof(h));
        return shared_page_layout(h).vertices;
    }
    return 0;
}

// The arrays of a page whose prefix is `prefix`, in increasing offsets.
std::vector<RecordArray> arrays_of(PageKind kind, AttributeFormat format, std::span<const uint8_t> prefix,
                                   size_t raw_bytes) {
    if (kind == PageKind::Geometry) {
        GeometryPageHeader h;
        std::memcpy(&h, prefix.data(), sizeof(h));
        const RecordArray nodes{sizeof(h), sizeof(PageNode), h.node_count};
        return {nodes, {nodes.end(), sizeof(Quad), h.quad_count, false, true}};
    }
    if (format == AttributeFormat::Shared) {
        SharedPageHeader h;
        std::memcpy(&h, prefix.data(), sizeof(h));
        const SharedPageLayout l = shared_page_layout(h);
        std::vector<RecordArray> arrays = {{l.vertices, sizeof(SharedVertex), h.vertex_count},
                                           {l.triangles, sizeof(SharedTriangle), h.triangle_count},
                                           {l.corners, 2, 3 * size_t(h.triangle_count), true}};
        if (h.has_tangents) arrays.push_back({l.tangents, 4, h.triangle_count});
        return arrays;
    }
    const size_t record = attribute_record_bytes(format);
    return {{0, record, raw_bytes / record}};
}

void put_u32(std::vector<uint8_t>& out, size_t v) {
    const uint32_t x = uint32_t(v);
    out.insert(out.end(), reinterpret_cast<const uint8_t*>(&x), reinterpret_cast<const uint8_t*>(&x) + 4);
}

void put_bytes(std::vector<uint8_t>& out, const uint8_t* p, size_t n) { out.insert(out.end(), p, p + n); }

std::vector<uint8_t> zstd_frame(std::span<const uint8_t> bytes, int level) {
    std::vector<uint8_t> packed(ZSTD_compressBound(bytes.size()));
    const size_t n = ZSTD_compress(packed.data(), packed.size(), bytes.data(), bytes.size(), level);
    if (ZSTD_isError(n)) return {};
    packed.resize(n);
    return packed;
}

// Reads a uint32 length and that many bytes from `in` at `at`.
bool take(std::span<const uint8_t> in, size_t& at, std::span<const uint8_t>& bytes) {
    uint32_t n;
    if (in.size() - at < 4) return false;
    std::memcpy(&n, in.data() + at, 4);
    at += 4;
    if (in.size() - at < n) return false;
    bytes = in.subspan(at, n);
    at += n;
    return true;
}

void put_encoded(std::vector<uint8_t>& out, const std::vector<uint8_t>& encoded) {
    put_u32(out, encoded.size());
    put_bytes(out, encoded.data(), encoded.size());
}

std::vector<uint8_t> encode_vertices(const void* records, size_t count, size_t stride) {
    std::vector<uint8_t> encoded(meshopt_encodeVertexBufferBound(count, stride));
    encoded.resize(meshopt_encodeVertexBuffer(encoded.data(), encoded.size(), records, count, stride));
    return encoded;
}

// A triangle list through meshopt's index-buffer codec (about a byte a
// triangle), which may rotate a triangle's corners: the encoded list is
// followed by one byte a triangle saying by how much (0..2), so the
// corners come back in their order (they are tied to the barycentrics).
// Written: the encoded list, then the rotations (each with its length).
bool put_triangles(std::vector<uint8_t>& out, const std::vector<uint32_t>& indices, size_t vertex_count) {
    std::vector<uint8_t> encoded(meshopt_encodeIndexBufferBound(indices.size(), vertex_count));
    encoded.resize(meshopt_encodeIndexBuffer(encoded.data(), encoded.size(), indices.data(), indices.size()));
    std::vector<uint32_t> decoded(indices.size());
    if (encoded.empty() ||
        meshopt_decodeIndexBuffer(decoded.data(), decoded.size(), 4, encoded.data(), encoded.size()) != 0)
        return false;
    std::vector<uint8_t> rotation(indices.size() / 3);
    for (size_t t = 0; t < rotation.size(); ++t) {
        const uint32_t* in = &indices[3 * t];
        const uint32_t* got = &decoded[3 * t];
        int r = 0;
        while (r < 3 && !(got[0] == in[r] && got[1] == in[(r + 1) % 3] && got[2] == in[(r + 2) % 3])) ++r;
        if (r == 3) return false;
        rotation[t] = uint8_t(r);
    }
    put_encoded(out, encoded);
    put_encoded(out, rotation);
    return true;
}

// put_triangles read back: `count` indices, each below vertex_count.
bool take_triangles(std::span<const uint8_t> in, size_t& at, std::vector<uint32_t>& indices, size_t count,
                    size_t vertex_count) {
    std::span<const uint8_t> encoded, rotation;
    indices.resize(count);
    if (count % 3 != 0 || !take(in, at, encoded) || !take(in, at, rotation) || rotation.size() != count / 3 ||
        meshopt_decodeIndexBuffer(indices.data(), count, 4, encoded.data(), encoded.size()) != 0)
        return false;
    for (size_t t = 0; t < rotation.size(); ++t) {
        const uint8_t r = rotation[t];
        uint32_t* tri = &indices[3 * t];
        if (r > 2 || tri[0] >= vertex_count || tri[1] >= vertex_count || tri[2] >= vertex_count) return false;
        const uint32_t got[3] = {tri[0], tri[1], tri[2]};  // got[k] = original[(r + k) % 3]
        for (int k = 0; k < 3; ++k) tri[(r + k) % 3] = got[k];
    }
    return true;
}

// A quantised vertex padded to the 4-byte multiple meshopt's vertex codec takes.
struct PaddedVertex {
    int16_t v[3];
    int16_t pad = 0;
};

// Quads as their distinct vertices (in first use order, so neighbouring
// vertices are near each other) and four indices a quad: uint32_t
// vertex_count, the encoded vertices, the encoded index sequence (smaller
// here than two triangles a quad through the index-buffer codec: leaf
// order is not the strip-like order that codec is made for).
bool put_quads(std::vector<uint8_t>& out, const uint8_t* raw, size_t count) {
    std::unordered_map<uint64_t, uint32_t> index_of;
    std::vector<PaddedVertex> vertices;
    std::vector<uint32_t> indices(4 * count);
    for (size_t q = 0; q < count; ++q) {
        Quad quad;
        std::memcpy(&quad, raw + q * sizeof(Quad), sizeof(Quad));
        for (int c = 0; c < 4; ++c) {
            const PaddedVertex v{{quad.v[c][0], quad.v[c][1], quad.v[c][2]}};
            const uint64_t key = uint64_t(uint16_t(v.v[0])) | uint64_t(uint16_t(v.v[1])) << 16 | uint64_t(uint16_t(v.v[2])) << 32;
            auto [it, added] = index_of.try_emplace(key, uint32_t(vertices.size()));
            if (added) vertices.push_back(v);
            indices[4 * q + size_t(c)] = it->second;
        }
    }
    std::vector<uint8_t> encoded(meshopt_encodeIndexSequenceBound(indices.size(), vertices.size()));
    encoded.resize(meshopt_encodeIndexSequence(encoded.data(), encoded.size(), indices.data(), indices.size()));
    put_u32(out, vertices.size());
    put_encoded(out, encode_vertices(vertices.data(), vertices.size(), sizeof(PaddedVertex)));
    put_encoded(out, encoded);
    return !encoded.empty();
}

// The meshopt stream of a raw page (before zstd); empty when the page is
// not laid out as its kind says (then it is stored with zstd alone).
std::vector<uint8_t> meshopt_stream(std::span<const uint8_t> raw, PageKind kind, AttributeFormat format) {
    const size_t prefix = prefix_bytes(kind, format, raw);
    if (prefix > raw.size()) return {};
    const std::vector<RecordArray> arrays = arrays_of(kind, format, raw.first(prefix), raw.size());
    std::vector<uint8_t> out;
    put_u32(out, prefix);
    put_bytes(out, raw.data(), prefix);
    size_t at = prefix;
    for (const RecordArray& a : arrays) {
        if (a.offset < at || a.end() > raw.size()) return {};
        for (size_t gap = at; gap < a.offset; ++gap)
            if (raw[gap] != 0) return {};  // gaps decode as zeros
        bool ok = true;
        if (a.quads) {
            ok = put_quads(out, raw.data() + a.offset, a.count);
        } else if (a.corners) {
            std::vector<uint32_t> indices(a.count);
            for (size_t i = 0; i < a.count; ++i) {
                uint16_t v;
                std::memcpy(&v, raw.data() + a.offset + 2 * i, 2);
                indices[i] = v;
            }
            ok = put_triangles(out, indices, 65536);
        } else {
            const std::vector<uint8_t> encoded =
                a.count == 0 ? std::vector<uint8_t>{} : encode_vertices(raw.data() + a.offset, a.count, a.stride);
            ok = a.count == 0 || !encoded.empty();
            put_encoded(out, encoded);
        }
        if (!ok) return {};
        at = a.end();
    }
    put_u32(out, raw.size() - at);
    put_bytes(out, raw.data() + at, raw.size() - at);
    return out;
}


// put_quads read back into `count` quads at `out`.
bool take_quads(std::span<const uint8_t> in, size_t& at, uint8_t* out, size_t count) {
    uint32_t vertex_count;
    std::span<const uint8_t> vertex_bytes, index_bytes;
    if (in.size() - at < 4) return false;
    std::memcpy(&vertex_count, in.data() + at, 4);
    at += 4;
    if (vertex_count > 4 * count || !take(in, at, vertex_bytes) || !take(in, at, index_bytes)) return false;
    thread_local std::vector<PaddedVertex> vertices;  // (a reader's, reused page after page)
    thread_local std::vector<uint32_t> indices;
    vertices.resize(vertex_count);
    indices.resize(4 * count);
    if (meshopt_decodeVertexBuffer(vertices.data(), vertex_count, sizeof(PaddedVertex), vertex_bytes.data(),
                                   vertex_bytes.size()) != 0 ||
        meshopt_decodeIndexSequence(indices.data(), indices.size(), 4, index_bytes.data(), index_bytes.size()) != 0)
        return false;
    for (size_t q = 0; q < count; ++q) {
        Quad quad;
        for (int c = 0; c < 4; ++c) {
            const uint32_t i = indices[4 * q + size_t(c)];
            if (i >= vertex_count) return false;
            for (int k = 0; k < 3; ++k) quad.v[c][k] = vertices[i].v[k];
        }
        std::memcpy(out + q * sizeof(Quad), &quad, sizeof(Quad));
    }
    return true;
}

bool decode_meshopt_stream(std::span<const uint8_t> in, PageKind kind, AttributeFormat format, std::span<uint8_t> raw) {
    size_t at = 0;
    std::span<const uint8_t> prefix;
    if (!take(in, at, prefix) || prefix.size() > raw.size()) return false;
    std::memcpy(raw.data(), prefix.data(), prefix.size());
    if (prefix_bytes(kind, format, prefix) != prefix.size()) return false;
    size_t filled = prefix.size();
    for (const RecordArray& a : arrays_of(kind, format, prefix, raw.size())) {
        if (a.offset < filled || a.count > raw.size() || a.end() > raw.size()) return false;
        std::memset(raw.data() + filled, 0, a.offset - filled);
        filled = a.end();
        if (a.quads) {
            if (!take_quads(in, at, raw.data() + a.offset, a.count)) return false;
            continue;
        }
        if (a.corners) {
            thread_local std::vector<uint32_t> indices;
            if (!take_triangles(in, at, indices, a.count, 65536)) return false;
            for (size_t i = 0; i < a.count; ++i) {
                const uint16_t v = uint16_t(indices[i]);
                std::memcpy(raw.data() + a.offset + 2 * i, &v, 2);
            }
            continue;
        }
        std::span<const uint8_t> encoded;
        if (!take(in, at, encoded)) return false;
        if (a.count == 0) {
            if (!encoded.empty()) return false;
        } else if (meshopt_decodeVertexBuffer(raw.data() + a.offset, a.count, a.stride, encoded.data(), encoded.size()) != 0) {
            return false;
        }
    }
    std::span<const uint8_t> tail;
    if (!take(in, at, tail) || at != in.size() || filled + tail.size() != raw.size()) return false;
    std::memcpy(raw.data() + filled, tail.data(), tail.size());
    return true;
}

}  // namespace

StoredPage encode_page(std::vector<uint8_t> raw, PageKind kind, AttributeFormat format, Codec codec, int zstd_level) {
    StoredPage s;
    s.raw_bytes = uint32_t(raw.size());
    // The smallest of: raw, zstd alone, and (Meshopt) the meshopt stream with zstd.
    s.bytes = std::move(raw);
    const auto keep_if_smaller = [&](std::vector<uint8_t> packed, Codec used) {
        if (!packed.empty() && packed.size() < s.bytes.size()) {
            s.bytes = std::move(packed);
            s.codec = used;
        }
    };
    std::vector<uint8_t> zstd_alone = codec != Codec::None ? zstd_frame(s.bytes, zstd_level) : std::vector<uint8_t>{};
    if (codec == Codec::Meshopt && kind != PageKind::TextureTile) {
        const std::vector<uint8_t> stream = meshopt_stream(s.bytes, kind, format);
        if (!stream.empty()) keep_if_smaller(zstd_frame(stream, zstd_level), Codec::Meshopt);
    }
    keep_if_smaller(std::move(zstd_alone), Codec::Zstd);
    return s;
}

namespace {

// A decompression context per thread: ZSTD_decompress would make one a
// call, which costs as much as decoding a small page.
ZSTD_DCtx* thread_dctx() {
    thread_local std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> dctx(ZSTD_createDCtx(), ZSTD_freeDCtx);
    return dctx.get();
}

size_t unzstd(std::span<uint8_t> out, std::span<const uint8_t> in) {
    return ZSTD_decompressDCtx(thread_dctx(), out.data(), out.size(), in.data(), in.size());
}

}  // namespace

bool decode_page(std::span<const uint8_t> stored, Codec codec, PageKind kind, AttributeFormat format,
                 std::span<uint8_t> raw) {
    if (codec == Codec::Zstd) {
        const size_t got = unzstd(raw, stored);
        return !ZSTD_isError(got) && got == raw.size();
    }
    if (codec != Codec::Meshopt || kind == PageKind::TextureTile) return false;
    // The stream is at most the raw page plus what the encoders add
    // (meshopt's bounds: a byte per 16 records per byte column, and tails).
    const unsigned long long size = ZSTD_getFrameContentSize(stored.data(), stored.size());
    if (size == ZSTD_CONTENTSIZE_UNKNOWN || size == ZSTD_CONTENTSIZE_ERROR || size > 2 * uint64_t(raw.size()) + 4096)
        return false;
    thread_local std::vector<uint8_t> scratch;
    scratch.resize(size_t(size));
    const size_t got = unzstd(scratch, stored);
    if (ZSTD_isError(got) || got != size) return false;
    return decode_meshopt_stream(scratch, kind, format, raw);
}

}  // namespace rf::pack
