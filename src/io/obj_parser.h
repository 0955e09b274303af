// The Wavefront OBJ statement parser, shared by the in-core loader
// (obj_loader.cpp, over a memory-mapped file) and the streaming converter
// (ooc/obj_stream_convert.cpp, over a file read in blocks): one line at a
// time, handing vertices, texture coordinates, normals and fan-triangulated
// faces to a sink. Indices are checked as they are read (negative ones are
// relative to the counts so far) and, for forward references, in finish().
//
// A Sink has: position(Vec3f), uv(Vec2f) (v already flipped: 0 at the top
// row), normal(Vec3f), triangle(const ObjCorner&, const ObjCorner&,
// const ObjCorner&, uint32_t material), where material indexes
// used_materials() or is kObjAbsent before the first usemtl.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "io/number_parsing.h"
#include "rayforge/core/error.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/scene.h"

namespace rf::io {

inline constexpr uint32_t kObjAbsent = 0xFFFFFFFFu;

struct ObjCorner {
    uint32_t v = 0, vt = kObjAbsent, vn = kObjAbsent;  // 0-based indices into the attribute arrays
};

// The largest positive index seen for one attribute and where, so that
// references to vertices defined later in the file are checked at the end.
struct ForwardReference {
    uint64_t max_index = 0;
    long line = 0;
    void note(uint64_t index, long at) {
        if (index > max_index) {
            max_index = index;
            line = at;
        }
    }
};

template <class Sink>
class ObjParser {
public:
    ObjParser(const std::string& path, Sink& sink) : path_(path), sink_(sink) {}

    // One line, without its '\n'.
    void line(std::string_view text) {
        ++line_;
        p_ = text.data();
        end_ = p_ + text.size();
        skip_space();
        if (p_ == end_) return;
        if (keyword("v")) {
            sink_.position(read_vec3("vertex position"));
            ++positions_;
        } else if (keyword("vt")) {
            float u = read_float("texture coordinate");
            float v = at_end() ? 0.0f : read_float("texture coordinate");
            // OBJ's v points up; ours has v = 0 at the top row of the image.
            sink_.uv(Vec2f{u, 1.0f - v});
            ++uvs_;
        } else if (keyword("vn")) {
            sink_.normal(read_vec3("normal"));
            ++normals_;
        } else if (keyword("f")) {
            read_face();
        } else if (keyword("usemtl")) {
            std::string name(rest_of_line());
            auto [it, inserted] = material_ids_.try_emplace(name, uint32_t(used_materials_.size()));
            if (inserted) used_materials_.push_back(name);
            material_ = it->second;
        } else if (keyword("mtllib")) {
            std::string_view names = rest_of_line();
            if (!names.empty()) libraries_.emplace_back(names);
        }
        // Everything else (o, g, s, l, p, comments, curves) does not affect triangles.
    }

    // Every line of `text`.
    void lines(std::string_view text) {
        size_t pos = 0;
        while (pos < text.size()) {
            size_t eol = text.find('\n', pos);
            if (eol == std::string_view::npos) eol = text.size();
            line(text.substr(pos, eol - pos));
            pos = eol + 1;
        }
    }

    // After the last line: indices that pointed past the end are errors.
    void finish() const {
        auto check = [&](const ForwardReference& f, uint64_t count, const char* what) {
            if (f.max_index > count)
                throw file_error(path_, f.line, std::string(what) + " index " + std::to_string(f.max_index) +
                                                    " out of range (" + std::to_string(count) + " in file)");
        };
        check(forward_v_, positions_, "vertex");
        check(forward_vt_, uvs_, "texture coordinate");
        check(forward_vn_, normals_, "normal");
    }

    [[nodiscard]] const std::vector<std::string>& used_materials() const { return used_materials_; }  // usemtl names, in order of first use
    [[nodiscard]] const std::vector<std::string>& libraries() const { return libraries_; }            // mtllib arguments
    [[nodiscard]] uint64_t skipped_faces() const { return skipped_faces_; }  // faces with fewer than 3 corners
    [[nodiscard]] uint64_t positions() const { return positions_; }
    [[nodiscard]] uint64_t uvs() const { return uvs_; }
    [[nodiscard]] uint64_t normals() const { return normals_; }
    [[nodiscard]] uint64_t triangles() const { return triangles_; }

private:
    [[nodiscard]] Error error(const std::string& reason) const { return file_error(path_, line_, reason); }

    void skip_space() {
        while (p_ < end_ && (*p_ == ' ' || *p_ == '\t' || *p_ == '\r')) ++p_;
    }
    bool at_end() {
        skip_space();
        return p_ == end_ || *p_ == '#';
    }
    // Consumes `word` when the line starts with it followed by whitespace.
    bool keyword(std::string_view word) {
        size_t left = size_t(end_ - p_);
        if (left < word.size() || std::string_view(p_, word.size()) != word) return false;
        if (left > word.size() && p_[word.size()] != ' ' && p_[word.size()] != '\t') return false;
        p_ += word.size();
        return true;
    }
    std::string_view rest_of_line() {
        skip_space();
        std::string_view rest(p_, size_t(end_ - p_));
        while (!rest.empty() && (rest.back() == ' ' || rest.back() == '\t' || rest.back() == '\r'))
            rest.remove_suffix(1);
        return rest;
    }

    float read_float(const char* what) {
        skip_space();
        float value = 0.0f;
        const char* after = io::parse_float(p_, end_, value);
        if (after == nullptr || (after < end_ && *after != ' ' && *after != '\t' && *after != '\r'))
            throw error(std::string("bad number '") + std::string(p_, std::min<size_t>(size_t(end_ - p_), 24)) +
                        "' in " + what);
        if (!std::isfinite(value)) throw error(std::string("non-finite number in ") + what);
        p_ = after;
        return value;
    }
    Vec3f read_vec3(const char* what) {
        float x = read_float(what);
        float y = read_float(what);
        float z = read_float(what);
        return {x, y, z};
    }

    // One index of a face corner: 1-based, or negative relative to the end so far.
    uint32_t resolve_index(uint64_t count_so_far, ForwardReference& forward, const char* what) {
        int64_t index = 0;
        const char* after = io::parse_int(p_, end_, index);
        if (after == nullptr) throw error(std::string("bad ") + what + " index in face");
        p_ = after;
        if (index == 0) throw error(std::string(what) + " index 0 in face (OBJ indices start at 1)");
        if (index < 0) {
            if (uint64_t(-index) > count_so_far)
                throw error(std::string(what) + " index " + std::to_string(index) + " out of range (" +
                            std::to_string(count_so_far) + " defined so far)");
            return uint32_t(count_so_far - uint64_t(-index));
        }
        if (uint64_t(index) > 0xFFFFFFFEull) throw error(std::string(what) + " index out of range");
        forward.note(uint64_t(index), line_);
        return uint32_t(index - 1);
    }

    void read_face() {
        face_.clear();
        while (!at_end()) {
            ObjCorner c;
            c.v = resolve_index(positions_, forward_v_, "vertex");
            if (p_ < end_ && *p_ == '/') {
                ++p_;
                if (p_ < end_ && *p_ != '/') c.vt = resolve_index(uvs_, forward_vt_, "texture coordinate");
                if (p_ < end_ && *p_ == '/') {
                    ++p_;
                    c.vn = resolve_index(normals_, forward_vn_, "normal");
                }
            }
            if (p_ < end_ && *p_ != ' ' && *p_ != '\t' && *p_ != '\r') throw error("malformed face corner");
            face_.push_back(c);
        }
        if (face_.size() < 3) {
            ++skipped_faces_;
            return;
        }
        // Fan triangulation, as most exporters write convex polygons.
        for (size_t k = 2; k < face_.size(); ++k) {
            sink_.triangle(face_[0], face_[k - 1], face_[k], material_);
            ++triangles_;
        }
    }

    const std::string& path_;
    Sink& sink_;
    const char* p_ = nullptr;
    const char* end_ = nullptr;
    long line_ = 0;
    uint64_t positions_ = 0, uvs_ = 0, normals_ = 0, triangles_ = 0, skipped_faces_ = 0;
    uint32_t material_ = kObjAbsent;
    std::vector<ObjCorner> face_;
    ForwardReference forward_v_, forward_vt_, forward_vn_;
    std::unordered_map<std::string, uint32_t> material_ids_;
    std::vector<std::string> used_materials_;
    std::vector<std::string> libraries_;
};

// The materials an OBJ file's faces use (its mtllib files, tinyobj::LoadMtl
// and the MTL -> glTF-style heuristics of obj_loader.cpp), added to `scene`
// with their textures; returns, for each name of `used_materials`, its index
// in scene.materials (a default material where a name is not defined).
std::vector<uint32_t> add_obj_materials(Scene& scene, const std::string& obj_path,
                                        const std::vector<std::string>& used_materials,
                                        const std::vector<std::string>& libraries, bool load_textures);

// A default material for faces before any usemtl (MTL's defaults).
Material default_obj_material(const std::string& name);

}  // namespace rf::io
