// PLY (Stanford polygon file format) loader: ascii, binary_little_endian and
// binary_big_endian bodies, arbitrary elements and properties.
// Format: Greg Turk, "The PLY Polygon File Format" (1994).
//
// Only `vertex` (x, y, z, optional normals and texture coordinates) and
// `face` (a vertex_indices / vertex_index list) are interpreted; every other
// element and property is skipped (vertex colours too). Every face gets one
// grey Lambertian material. Polygons are fan-triangulated. The header's
// counts are checked against the file size before anything is allocated.
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "io/file_reader.h"
#include "io/number_parsing.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/scene_io.h"

namespace rf {

namespace {

enum class PlyType : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

size_t type_size(PlyType type) {
    switch (type) {
        case PlyType::Int8: case PlyType::UInt8: return 1;
        case PlyType::Int16: case PlyType::UInt16: return 2;
        case PlyType::Int32: case PlyType::UInt32: case PlyType::Float32: return 4;
        case PlyType::Float64: return 8;
    }
    return 1;
}

bool is_integer_type(PlyType type) { return type != PlyType::Float32 && type != PlyType::Float64; }

std::optional<PlyType> parse_type(std::string_view name) {
    if (name == "char" || name == "int8") return PlyType::Int8;
    if (name == "uchar" || name == "uint8") return PlyType::UInt8;
    if (name == "short" || name == "int16") return PlyType::Int16;
    if (name == "ushort" || name == "uint16") return PlyType::UInt16;
    if (name == "int" || name == "int32") return PlyType::Int32;
    if (name == "uint" || name == "uint32") return PlyType::UInt32;
    if (name == "float" || name == "float32") return PlyType::Float32;
    if (name == "double" || name == "float64") return PlyType::Float64;
    return std::nullopt;
}

// What a property of the vertex or face element means to us.
enum class Role : uint8_t { Skip, X, Y, Z, NX, NY, NZ, U, V, FaceIndices };

struct PlyProperty {
    std::string name;
    PlyType type = PlyType::Float32;   // item type for lists
    bool is_list = false;
    PlyType count_type = PlyType::UInt8;
    Role role = Role::Skip;
};

struct PlyElement {
    std::string name;
    uint64_t count = 0;
    std::vector<PlyProperty> properties;
};

enum class PlyFormat { Ascii, BinaryLittleEndian, BinaryBigEndian };

struct PlyHeader {
    PlyFormat format = PlyFormat::Ascii;
    std::vector<PlyElement> elements;
    size_t body_offset = 0;  // first byte after "end_header\n"
    long body_line = 1;      // line number of the first body line (ascii errors)
};

std::vector<std::string_view> split_words(std::string_view line) {
    std::vector<std::string_view> words;
    size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
        size_t start = i;
        while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
        if (i > start) words.push_back(line.substr(start, i - start));
    }
    return words;
}

Role vertex_role(std::string_view name) {
    if (name == "x") return Role::X;
    if (name == "y") return Role::Y;
    if (name == "z") return Role::Z;
    if (name == "nx") return Role::NX;
    if (name == "ny") return Role::NY;
    if (name == "nz") return Role::NZ;
    if (name == "u" || name == "s" || name == "texture_u" || name == "texture_s") return Role::U;
    if (name == "v" || name == "t" || name == "texture_v" || name == "texture_t") return Role::V;
    return Role::Skip;
}

PlyHeader parse_header(const std::string& path, std::string_view data) {
    PlyHeader header;
    size_t pos = 0;
    long line_number = 0;
    bool have_format = false;
    auto fail = [&](const std::string& reason) { return file_error(path, line_number, reason); };

    while (true) {
        if (pos >= data.size()) {
            ++line_number;
            throw fail("header has no end_header line");
        }
        size_t eol = data.find('\n', pos);
        if (eol == std::string_view::npos) eol = data.size();
        std::string_view line = data.substr(pos, eol - pos);
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        pos = eol + 1;
        ++line_number;

        std::vector<std::string_view> words = split_words(line);
        if (line_number == 1) {
            if (words.size() != 1 || words[0] != "ply") throw fail("not a PLY file (first line is not 'ply')");
            continue;
        }
        if (words.empty()) continue;
        const std::string_view keyword = words[0];
        if (keyword == "comment" || keyword == "obj_info") continue;
        if (keyword == "end_header") {
            if (!have_format) throw fail("end_header before the format line");
            header.body_offset = std::min(pos, data.size());
            header.body_line = line_number + 1;
            return header;
        }
        if (keyword == "format") {
            if (words.size() < 2) throw fail("format line without a format");
            if (words[1] == "ascii") header.format = PlyFormat::Ascii;
            else if (words[1] == "binary_little_endian") header.format = PlyFormat::BinaryLittleEndian;
            else if (words[1] == "binary_big_endian") header.format = PlyFormat::BinaryBigEndian;
            else throw fail("unknown format '" + std::string(words[1]) + "'");
            have_format = true;
        } else if (keyword == "element") {
            if (words.size() != 3) throw fail("expected 'element NAME COUNT'");
            PlyElement element;
            element.name = std::string(words[1]);
            auto [end, ec] = std::from_chars(words[2].data(), words[2].data() + words[2].size(), element.count);
            if (ec != std::errc() || end != words[2].data() + words[2].size())
                throw fail("bad element count '" + std::string(words[2]) + "'");
            header.elements.push_back(std::move(element));
        } else if (keyword == "property") {
            if (header.elements.empty()) throw fail("property before any element");
            PlyProperty property;
            if (words.size() >= 2 && words[1] == "list") {
                if (words.size() != 5) throw fail("expected 'property list COUNT_TYPE ITEM_TYPE NAME'");
                std::optional<PlyType> count_type = parse_type(words[2]), item_type = parse_type(words[3]);
                if (!count_type || !item_type) throw fail("unknown property type in list");
                if (!is_integer_type(*count_type)) throw fail("list count type must be an integer type");
                property.is_list = true;
                property.count_type = *count_type;
                property.type = *item_type;
                property.name = std::string(words[4]);
            } else {
                if (words.size() != 3) throw fail("expected 'property TYPE NAME'");
                std::optional<PlyType> type = parse_type(words[1]);
                if (!type) throw fail("unknown property type '" + std::string(words[1]) + "'");
                property.type = *type;
                property.name = std::string(words[2]);
            }
            PlyElement& element = header.elements.back();
            if (element.name == "vertex" && !property.is_list) property.role = vertex_role(property.name);
            if (element.name == "face" && property.is_list &&
                (property.name == "vertex_indices" || property.name == "vertex_index")) {
                if (!is_integer_type(property.type)) throw fail("face indices must have an integer type");
                property.role = Role::FaceIndices;
            }
            element.properties.push_back(std::move(property));
        } else {
            throw fail("unknown header keyword '" + std::string(keyword) + "'");
        }
    }
}

// The fewest body bytes one element can take: rejects absurd counts before allocating.
uint64_t min_element_bytes(const PlyElement& element, PlyFormat format) {
    uint64_t bytes = 0;
    for (const PlyProperty& p : element.properties) {
        if (format == PlyFormat::Ascii) bytes += 2;  // one digit and one separator per value
        else bytes += type_size(p.is_list ? p.count_type : p.type);
    }
    return bytes;
}

// Every element needs at least min_element_bytes: a count that cannot fit in
// the rest of the body is rejected here, before anything is allocated.
void check_counts_fit(const std::string& path, const PlyHeader& header, uint64_t body_bytes) {
    uint64_t budget = body_bytes + 1;  // +1: the last ascii value may lack its separator
    for (const PlyElement& element : header.elements) {
        if (element.properties.empty()) continue;  // nothing to read, skipped without looping
        const uint64_t per = min_element_bytes(element, header.format);
        if (element.count > budget / per)
            throw file_error(path, 0, "header declares " + std::to_string(element.count) + " '" + element.name +
                                          "' elements but the body has only " + std::to_string(body_bytes) + " bytes");
        budget -= element.count * per;
    }
}

// Reads values from a binary body; errors carry the byte offset.
class BinaryReader {
public:
    BinaryReader(const std::string& path, std::string_view data, size_t offset, bool swap)
        : path_(path), data_(data), pos_(offset), swap_(swap) {}

    double number(PlyType type) {
        switch (type) {
            case PlyType::Int8: return double(load<int8_t>());
            case PlyType::UInt8: return double(load<uint8_t>());
            case PlyType::Int16: return double(load<int16_t>());
            case PlyType::UInt16: return double(load<uint16_t>());
            case PlyType::Int32: return double(load<int32_t>());
            case PlyType::UInt32: return double(load<uint32_t>());
            case PlyType::Float32: return double(load<float>());
            case PlyType::Float64: return load<double>();
        }
        return 0.0;
    }
    // Integer-typed values (list counts and indices); float types never get here.
    int64_t integer(PlyType type) {
        switch (type) {
            case PlyType::Int8: return load<int8_t>();
            case PlyType::UInt8: return load<uint8_t>();
            case PlyType::Int16: return load<int16_t>();
            case PlyType::UInt16: return load<uint16_t>();
            case PlyType::Int32: return load<int32_t>();
            case PlyType::UInt32: return load<uint32_t>();
            default: return int64_t(number(type));
        }
    }
    void skip(PlyType type, uint64_t count) {
        uint64_t bytes = count * type_size(type);
        if (count > data_.size() || bytes > data_.size() - pos_) throw truncated();
        pos_ += size_t(bytes);
    }
    void mark() { mark_ = pos_; }
    [[nodiscard]] Error error(const std::string& reason) const { return file_byte_error(path_, mark_, reason); }

private:
    template <typename T>
    T load() {
        if (sizeof(T) > data_.size() - pos_) throw truncated();
        unsigned char bytes[sizeof(T)];
        std::memcpy(bytes, data_.data() + pos_, sizeof(T));
        if (swap_)
            for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
        T value;
        std::memcpy(&value, bytes, sizeof(T));
        pos_ += sizeof(T);
        return value;
    }
    [[nodiscard]] Error truncated() const {
        return file_byte_error(path_, pos_, "unexpected end of file (truncated body)");
    }

    const std::string& path_;
    std::string_view data_;
    size_t pos_;
    size_t mark_ = 0;
    bool swap_;
};

// Reads whitespace-separated values from an ascii body; errors carry the line.
class AsciiReader {
public:
    AsciiReader(const std::string& path, std::string_view data, size_t offset, long line)
        : path_(path), p_(data.data() + offset), end_(data.data() + data.size()), line_(line) {}

    double number(PlyType type) {
        std::string_view token = next();
        const char* first = token.data();
        const char* last = first + token.size();
        const char* after = nullptr;
        double value = 0.0;
        if (type == PlyType::Float32) {
            float f = 0.0f;  // parsed as float so the value matches a binary file exactly
            after = io::parse_float(first, last, f);
            value = f;
        } else if (type == PlyType::Float64) {
            if (first < last && *first == '+') ++first;  // from_chars rejects '+'
            auto [ptr, ec] = std::from_chars(first, last, value);
            after = ec == std::errc() ? ptr : nullptr;
        } else {
            int64_t i = 0;
            after = io::parse_int(first, last, i);
            value = double(i);
        }
        if (after != last) throw file_error(path_, line_, "bad number '" + std::string(token.substr(0, 32)) + "'");
        return value;
    }
    int64_t integer(PlyType) {
        std::string_view token = next();
        int64_t value = 0;
        if (io::parse_int(token.data(), token.data() + token.size(), value) != token.data() + token.size())
            throw file_error(path_, line_, "bad integer '" + std::string(token.substr(0, 32)) + "'");
        return value;
    }
    void skip(PlyType, uint64_t count) {
        for (uint64_t i = 0; i < count; ++i) next();
    }
    // Remembers the line of the next value, for errors about the element that starts there.
    void mark() {
        skip_space();
        mark_ = line_;
    }
    [[nodiscard]] Error error(const std::string& reason) const { return file_error(path_, mark_, reason); }

private:
    void skip_space() {
        while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r' || *p_ == '\n')) {
            if (*p_ == '\n') ++line_;
            ++p_;
        }
    }
    std::string_view next() {
        skip_space();
        if (p_ == end_) throw file_error(path_, line_, "unexpected end of file (truncated body)");
        const char* start = p_;
        while (p_ < end_ && *p_ != ' ' && *p_ != '\t' && *p_ != '\r' && *p_ != '\n') ++p_;
        return {start, size_t(p_ - start)};
    }

    const std::string& path_;
    const char* p_;
    const char* end_;
    long line_;
    long mark_ = 0;
};

template <typename Reader>
void skip_element(Reader& reader, const PlyElement& element) {
    if (element.properties.empty()) return;
    for (uint64_t i = 0; i < element.count; ++i)
        for (const PlyProperty& p : element.properties) {
            if (p.is_list) {
                int64_t n = reader.integer(p.count_type);
                if (n < 0) throw reader.error("negative list length in element '" + element.name + "'");
                reader.skip(p.type, uint64_t(n));
            } else {
                reader.skip(p.type, 1);
            }
        }
}

template <typename Reader>
void read_vertices(Reader& reader, const PlyElement& element, Mesh& mesh, const std::string& path) {
    bool has_normals = false, has_uvs = false;
    int xyz = 0;
    for (const PlyProperty& p : element.properties) {
        if (p.role == Role::X || p.role == Role::Y || p.role == Role::Z) ++xyz;
        if (p.role == Role::NX) has_normals = true;
        if (p.role == Role::U) has_uvs = true;
    }
    if (xyz != 3) throw reader.error("vertex element lacks x, y or z");

    const size_t n = size_t(element.count);
    budgeted_resize(mesh.positions, n, path + ": PLY vertex array");
    if (has_normals) budgeted_resize(mesh.normals, n, path + ": PLY normal array");
    if (has_uvs) budgeted_resize(mesh.uvs, n, path + ": PLY texture coordinate array");
    for (size_t i = 0; i < n; ++i) {
        reader.mark();
        Vec3f p{}, nrm{};
        Vec2f uv{};
        for (const PlyProperty& prop : element.properties) {
            if (prop.is_list) {
                int64_t count = reader.integer(prop.count_type);
                if (count < 0) throw reader.error("negative list length in vertex " + std::to_string(i));
                reader.skip(prop.type, uint64_t(count));
                continue;
            }
            if (prop.role == Role::Skip) {
                reader.skip(prop.type, 1);
                continue;
            }
            float value = float(reader.number(prop.type));
            switch (prop.role) {
                case Role::X: p.x = value; break;
                case Role::Y: p.y = value; break;
                case Role::Z: p.z = value; break;
                case Role::NX: nrm.x = value; break;
                case Role::NY: nrm.y = value; break;
                case Role::NZ: nrm.z = value; break;
                case Role::U: uv.x = value; break;
                case Role::V: uv.y = value; break;
                default: break;
            }
        }
        if (!is_finite(p)) throw reader.error("vertex " + std::to_string(i) + " has a non-finite coordinate");
        mesh.positions[i] = p;
        if (has_normals) {
            if (!is_finite(nrm)) throw reader.error("vertex " + std::to_string(i) + " has a non-finite normal");
            mesh.normals[i] = nrm;
        }
        // PLY texture coordinates have v pointing up; ours have v = 0 at the top row.
        if (has_uvs) mesh.uvs[i] = Vec2f{uv.x, 1.0f - uv.y};
    }
}

template <typename Reader>
void read_faces(Reader& reader, const PlyElement& element, uint64_t vertex_count, Mesh& mesh,
                const std::string& path) {
    bool has_indices = false;
    for (const PlyProperty& p : element.properties) has_indices |= p.role == Role::FaceIndices;
    if (!has_indices) throw reader.error("face element has no vertex_indices list");

    // One triangle per face is the common case; polygons grow the array under the budget too.
    const std::string what = path + ": PLY index array";
    if (element.count > std::numeric_limits<size_t>::max() / 3)
        throw Error(what + ": " + std::to_string(element.count) + " x 3 indices overflows");
    budgeted_reserve(mesh.indices, size_t(element.count) * 3, what);
    for (uint64_t f = 0; f < element.count; ++f) {
        reader.mark();
        for (const PlyProperty& prop : element.properties) {
            if (!prop.is_list) {
                reader.skip(prop.type, 1);
                continue;
            }
            int64_t count = reader.integer(prop.count_type);
            if (count < 0) throw reader.error("negative list length in face " + std::to_string(f));
            if (prop.role != Role::FaceIndices) {
                reader.skip(prop.type, uint64_t(count));
                continue;
            }
            // Fan triangulation as the indices stream in: no per-face allocation.
            uint32_t first = 0, previous = 0;
            for (int64_t k = 0; k < count; ++k) {
                int64_t index = reader.integer(prop.type);
                if (index < 0 || uint64_t(index) >= vertex_count)
                    throw reader.error("face " + std::to_string(f) + " references vertex " + std::to_string(index) +
                                       " of " + std::to_string(vertex_count));
                uint32_t v = uint32_t(index);
                if (k == 0) first = v;
                if (k >= 2) {
                    if (mesh.indices.capacity() - mesh.indices.size() < 3)
                        budgeted_reserve(mesh.indices, 2 * mesh.indices.size() + 3, what);
                    mesh.indices.push_back(first);
                    mesh.indices.push_back(previous);
                    mesh.indices.push_back(v);
                }
                previous = v;
            }
        }
    }
}

template <typename Reader>
void read_body(Reader& reader, const PlyHeader& header, Mesh& mesh, const std::string& path) {
    uint64_t vertex_count = 0;
    bool have_vertices = false, have_faces = false;
    for (const PlyElement& element : header.elements)
        if (element.name == "vertex") vertex_count = element.count;
    for (const PlyElement& element : header.elements) {
        if (element.name == "vertex" && !have_vertices) {
            read_vertices(reader, element, mesh, path);
            have_vertices = true;
        } else if (element.name == "face" && !have_faces) {
            read_faces(reader, element, vertex_count, mesh, path);
            have_faces = true;
        } else {
            skip_element(reader, element);
        }
    }
}

}  // namespace

Scene load_ply(const std::string& path, const LoadOptions& options) {
    const io::MappedFile file(path);
    const std::string_view data = file.bytes();
    PlyHeader header = parse_header(path, data);

    const PlyElement* vertices = nullptr;
    const PlyElement* faces = nullptr;
    for (const PlyElement& element : header.elements) {
        if (element.name == "vertex" && !vertices) vertices = &element;
        if (element.name == "face" && !faces) faces = &element;
    }
    if (!vertices) throw file_error(path, 0, "no vertex element");
    if (!faces || faces->count == 0) throw file_error(path, 0, "no faces (point clouds are not supported)");
    check_counts_fit(path, header, data.size() - header.body_offset);
    checked_index_count(path + ": PLY vertex count", vertices->count);

    Mesh mesh;
    mesh.name = std::filesystem::path(path).stem().string();
    if (header.format == PlyFormat::Ascii) {
        AsciiReader reader(path, data, header.body_offset, header.body_line);
        read_body(reader, header, mesh, path);
    } else {
        const bool big_endian_host = std::endian::native == std::endian::big;
        const bool file_big_endian = header.format == PlyFormat::BinaryBigEndian;
        BinaryReader reader(path, data, header.body_offset, big_endian_host != file_big_endian);
        read_body(reader, header, mesh, path);
    }
    if (mesh.indices.empty()) throw file_error(path, 0, "no triangles (every face has fewer than 3 vertices)");
    checked_index_count(path + ": PLY triangle count", mesh.indices.size() / 3);
    budgeted_resize(mesh.material_ids, mesh.indices.size() / 3, path + ": PLY material id array");
    if (mesh.normals.empty() && options.compute_missing_normals) mesh.compute_vertex_normals();

    Scene scene;
    scene.source = path;
    // PLY has no material model (vertex colours are not read): one grey
    // Lambertian, without the specular layer the glTF-style default carries.
    Material lambert;
    lambert.name = "default";
    lambert.specular = 0.0f;
    scene.materials.push_back(lambert);
    scene.meshes.push_back(std::move(mesh));
    scene.finalize();
    return scene;
}

}  // namespace rf
