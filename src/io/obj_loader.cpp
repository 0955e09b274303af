// Wavefront OBJ + MTL loader.
//
// The OBJ geometry is parsed here (file memory-mapped, io/number_parsing.h):
// tinyobjloader's parser takes several seconds on million-triangle files.
// MTL files are parsed by tinyobj::LoadMtl and mapped onto the glTF-style
// rf::Material (see material_from_mtl for the heuristics).
//
// OBJ indexes positions, texture coordinates and normals separately; the
// mesh gets one vertex per distinct (v, vt, vn) triple. The whole file
// becomes one rf::Mesh with a material per triangle.
#include <tiny_obj_loader.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "io/file_reader.h"
#include "io/obj_parser.h"
#include "io/texture_batch.h"
#include "io/number_parsing.h"
#include "io/path_utils.h"
#include "io/phong_material.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"

namespace rf {

namespace {

using io::ObjCorner;
constexpr uint32_t kAbsent = io::kObjAbsent;

void warn(const std::string& message) { std::cerr << "rayforge: warning: " << message << '\n'; }

// ---------------------------------------------------------------------------
// Geometry

// The whole file's statements in memory (obj_parser.h's sink).
struct ObjGeometry {
    explicit ObjGeometry(const std::string& path)
        : positions_what(path + ": OBJ vertex array"), uvs_what(path + ": OBJ texture coordinate array"),
          normals_what(path + ": OBJ normal array"), corners_what(path + ": OBJ face corner array") {}

    std::vector<Vec3f> positions;
    std::vector<Vec2f> uvs;
    std::vector<Vec3f> normals;
    std::vector<ObjCorner> corners;           // 3 per triangle
    std::vector<uint32_t> triangle_material;  // per triangle: index into the used materials, or kAbsent
    const std::string positions_what, uvs_what, normals_what, corners_what;  // budget error prefixes

    void position(Vec3f p) { budgeted_push_back(positions, p, positions_what); }
    void uv(Vec2f t) { budgeted_push_back(uvs, t, uvs_what); }
    void normal(Vec3f n) { budgeted_push_back(normals, n, normals_what); }
    void triangle(const ObjCorner& a, const ObjCorner& b, const ObjCorner& c, uint32_t material) {
        if (corners.capacity() - corners.size() < 3) budgeted_reserve(corners, 2 * corners.size() + 3, corners_what);
        corners.push_back(a);
        corners.push_back(b);
        corners.push_back(c);
        budgeted_push_back(triangle_material, material, corners_what);
    }
};

// One mesh vertex per distinct (v, vt, vn). Variants of a position are chained
// from first_variant[v]: a hash map whose hash is the position index itself.
Mesh build_mesh(const std::string& path, const ObjGeometry& geo, const std::vector<uint32_t>& triangle_material,
                bool compute_normals) {
    const bool any_uv = std::any_of(geo.corners.begin(), geo.corners.end(), [](const ObjCorner& c) { return c.vt != kAbsent; });
    const bool any_normal = std::any_of(geo.corners.begin(), geo.corners.end(), [](const ObjCorner& c) { return c.vn != kAbsent; });

    std::vector<uint32_t> first_variant(geo.positions.size(), kAbsent);
    std::vector<uint32_t> next_variant;
    std::vector<ObjCorner> vertex_key;
    next_variant.reserve(geo.positions.size());
    vertex_key.reserve(geo.positions.size());

    Mesh mesh;
    budgeted_resize(mesh.indices, geo.corners.size(), path + ": OBJ index array");
    for (size_t i = 0; i < geo.corners.size(); ++i) {
        const ObjCorner& c = geo.corners[i];
        uint32_t found = first_variant[c.v];
        while (found != kAbsent && (vertex_key[found].vt != c.vt || vertex_key[found].vn != c.vn))
            found = next_variant[found];
        if (found == kAbsent) {
            found = uint32_t(vertex_key.size());
            vertex_key.push_back(c);
            next_variant.push_back(first_variant[c.v]);
            first_variant[c.v] = found;
        }
        mesh.indices[i] = found;
    }

    const size_t n = vertex_key.size();
    budgeted_resize(mesh.positions, n, path + ": OBJ vertex array");
    for (size_t i = 0; i < n; ++i) mesh.positions[i] = geo.positions[vertex_key[i].v];
    if (any_uv) {
        budgeted_resize(mesh.uvs, n, path + ": OBJ texture coordinate array");
        for (size_t i = 0; i < n; ++i)
            if (vertex_key[i].vt != kAbsent) mesh.uvs[i] = geo.uvs[vertex_key[i].vt];
    }
    mesh.material_ids = triangle_material;

    const bool all_normals = std::all_of(vertex_key.begin(), vertex_key.end(), [](const ObjCorner& c) { return c.vn != kAbsent; });
    if (any_normal && all_normals) {
        budgeted_resize(mesh.normals, n, path + ": OBJ normal array");
        for (size_t i = 0; i < n; ++i) mesh.normals[i] = geo.normals[vertex_key[i].vn];
    } else if (compute_normals) {
        // Vertices without a normal get the computed one; the file's normals are kept.
        mesh.compute_vertex_normals();
        for (size_t i = 0; i < n; ++i)
            if (vertex_key[i].vn != kAbsent) mesh.normals[i] = geo.normals[vertex_key[i].vn];
    }
    return mesh;
}

// ---------------------------------------------------------------------------
// Materials

// Which statements one MTL material wrote: tinyobj reads an absent Ni as 1
// and an absent illum as 0, both of which mean something else when written.
struct MtlStatements {
    bool ni = false, illum = false;
};

struct MaterialLibrary {
    std::string path;  // the .mtl file, for resolving texture names
    std::vector<tinyobj::material_t> materials;
    std::vector<MtlStatements> statements;  // parallel to materials
    std::map<std::string, int> by_name;
};

// The statements of each material in tinyobj's order (one per `newmtl` with
// a non-empty name; tinyobj trims trailing blanks and skips leading ones).
std::vector<MtlStatements> scan_mtl_statements(std::string_view text) {
    std::vector<MtlStatements> out;
    auto starts = [](std::string_view line, std::string_view word) {
        return line.size() > word.size() && line.substr(0, word.size()) == word &&
               (line[word.size()] == ' ' || line[word.size()] == '\t');
    };
    for (size_t pos = 0; pos < text.size();) {
        size_t eol = std::min(text.find('\n', pos), text.size());
        std::string_view line = text.substr(pos, eol - pos);
        pos = eol + 1;
        while (!line.empty() && (line.back() == ' ' || line.back() == '\t' || line.back() == '\r')) line.remove_suffix(1);
        while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
        if (starts(line, "newmtl")) out.push_back({});
        else if (out.empty()) continue;
        else if (starts(line, "Ni")) out.back().ni = true;
        else if (starts(line, "illum")) out.back().illum = true;
    }
    return out;
}

std::vector<MaterialLibrary> load_material_libraries(const std::string& obj_path,
                                                     const std::vector<std::string>& arguments) {
    std::vector<MaterialLibrary> libraries;
    std::set<std::string> seen;
    for (const std::string& argument : arguments) {
        // Usually one file per mtllib line, but several may be listed; names with spaces exist too.
        std::vector<std::string> names{argument};
        if (!io::find_file_case_insensitive(io::resolve_relative(obj_path, argument))) {
            std::istringstream words(argument);
            names.clear();
            for (std::string w; words >> w;) names.push_back(w);
        }
        for (const std::string& name : names) {
            std::string resolved = io::resolve_relative(obj_path, name);
            std::optional<std::string> found = io::find_file_case_insensitive(resolved);
            if (!found) {
                warn(obj_path + ": material library '" + name + "' not found");
                continue;
            }
            if (!seen.insert(*found).second) continue;
            MaterialLibrary library;
            library.path = *found;
            std::istringstream stream(io::read_file(*found));
            std::string warnings, errors;
            tinyobj::LoadMtl(&library.by_name, &library.materials, &stream, &warnings, &errors);
            library.statements = scan_mtl_statements(stream.str());
            if (library.statements.size() != library.materials.size()) library.statements.clear();
            if (!errors.empty()) warn(*found + ": " + errors.substr(0, errors.find('\n')));
            libraries.push_back(std::move(library));
        }
    }
    return libraries;
}

// MTL's illumination models (illum 0-10), grouped by what they ask for.
enum class MtlModel { Diffuse, Highlight, Mirror, Glass };

MtlModel mtl_model(int illum, bool written) {
    if (!written) return MtlModel::Highlight;  // no illum line: Kd and Ks as written
    switch (illum) {
        case 0:  // "colour on, ambient off": unlit colour has no physical
        case 1:  // counterpart, so like 1 (diffuse only): a lit Lambertian
            return MtlModel::Diffuse;
        case 3:  // ray-traced reflection
        case 5:  // ... with Fresnel (Schlick from Ks, which a metal is)
        case 8:  // reflection without ray tracing: the same surface
            return MtlModel::Mirror;
        case 4: case 6: case 7: case 9:  // glass / refraction
            return MtlModel::Glass;
        default:  // 2 (highlight), 10 (shadow matte: no such thing here), unknown
            return MtlModel::Highlight;
    }
}

// Transmissive: a smooth interface (MTL's refraction is ray traced, Ns only
// shapes highlights) of index Ni, tinted by Tf. Its reflection is the
// interface's Fresnel term, so Ks does not scale it. Ni 1 is index-matched;
// without Ni, or with Ni < 1 (exporters write 0 for "unset"), ior is 1.5.
void set_mtl_glass(const tinyobj::material_t& m, bool ni_written, Material& out) {
    const Vec3f tf{m.transmittance[0], m.transmittance[1], m.transmittance[2]};
    out.transmission = 1.0f;
    out.base_color = max_component(tf) > 0.0f ? min(max(tf, Vec3f(0.0f)), Vec3f(1.0f)) : Vec3f(1.0f);
    out.ior = ni_written && m.ior >= 1.0f ? float(m.ior) : 1.5f;
    out.roughness = 0.0f;
}

// MTL onto the material model (the Ks/Ns rules are io/phong_material.h's):
// Kd is the base colour, Ke the emission; illum picks the model (mtl_model);
// opaque materials keep ior 1.5 for their specular layer (Ni is for
// refraction); d < 1 (or Tr > 0) on an opaque model is alpha blending.
Material material_from_mtl(const tinyobj::material_t& m, MtlStatements written) {
    Material out;
    out.name = m.name;
    const Vec3f kd{m.diffuse[0], m.diffuse[1], m.diffuse[2]};
    const Vec3f ks{m.specular[0], m.specular[1], m.specular[2]};
    const float ns = float(m.shininess);
    out.base_color = kd;
    out.emission = Vec3f{m.emission[0], m.emission[1], m.emission[2]};
    const MtlModel model = mtl_model(m.illum, written.illum);
    switch (model) {
        case MtlModel::Diffuse: io::set_phong_specular(Vec3f(0.0f), ns, out); break;
        case MtlModel::Highlight: io::set_phong_specular(ks, ns, out); break;
        case MtlModel::Mirror:
            if (io::phong_mirror(kd, ks)) io::set_phong_mirror(ks, ns, out);
            else io::set_phong_specular(ks, ns, out);
            break;
        case MtlModel::Glass: set_mtl_glass(m, written.ni, out); break;
    }
    if (model != MtlModel::Glass && m.dissolve < 1.0f) {
        out.alpha = std::clamp(float(m.dissolve), 0.0f, 1.0f);
        out.alpha_mode = AlphaMode::Blend;
    }
    return out;
}

using io::default_obj_material;

// The textures one material asks for, as resolved file paths ("" = none).
struct MaterialTextures {
    std::string base_color, mask, emission, normal;
    bool normal_is_bump = false;  // from map_bump/bump: used only if it looks like a normal map
};

// Decoded texture files (each decoded once) and the scene textures made from them.
class TextureTable {
public:
    explicit TextureTable(bool enabled) : enabled_(enabled) {}

    // Resolves an MTL texture name; "" when absent (warned once per name).
    std::string request(const MaterialLibrary& library, const std::string& name) {
        if (!enabled_ || name.empty()) return {};
        std::string resolved = io::resolve_relative(library.path, name);
        std::optional<std::string> found = io::find_file_case_insensitive(resolved);
        if (!found) {
            if (missing_.insert(resolved).second)
                warn(library.path + ": texture '" + name + "' not found; using the material's factor");
            return {};
        }
        if (!slot_.count(*found)) {
            slot_[*found] = paths_.size();
            paths_.push_back(*found);
        }
        return *found;
    }

    // Decodes every requested file, in parallel; failures become warnings.
    void decode_all() {
        decoded_ = decode_textures(paths_, "the material's factor");
    }

    const Texture* decoded(const std::string& path) const {
        auto it = slot_.find(path);
        if (it == slot_.end() || !decoded_[it->second]) return nullptr;
        return &*decoded_[it->second];
    }

    // The scene texture for (path, encoding), added on first use.
    int32_t scene_texture(Scene& scene, const std::string& path, TextureEncoding encoding) {
        const Texture* source = decoded(path);
        if (!source) return kNoTexture;
        auto key = std::make_pair(path, encoding);
        auto it = scene_index_.find(key);
        if (it != scene_index_.end()) return it->second;
        Texture texture = *source;
        if (texture.encoding != TextureEncoding::LinearFloat) texture.encoding = encoding;
        scene.textures.push_back(std::move(texture));
        return scene_index_[key] = int32_t(scene.textures.size() - 1);
    }

    // The base color texture with the map_d mask in its alpha channel.
    int32_t masked_texture(Scene& scene, const std::string& base_path, const std::string& mask_path) {
        const Texture* mask = decoded(mask_path);
        if (!mask) return base_path.empty() ? kNoTexture : scene_texture(scene, base_path, TextureEncoding::Srgb8);
        auto key = std::make_pair(base_path + "\n" + mask_path, TextureEncoding::Srgb8);
        auto it = scene_index_.find(key);
        if (it != scene_index_.end()) return it->second;
        scene.textures.push_back(merge_mask(decoded(base_path), *mask));
        return scene_index_[key] = int32_t(scene.textures.size() - 1);
    }

private:
    // RGBA8: color from `base` (white when absent), alpha from the mask,
    // sampled nearest-neighbour when the sizes differ.
    static Texture merge_mask(const Texture* base, const Texture& mask) {
        Texture out;
        const bool have_base = base && base->encoding != TextureEncoding::LinearFloat;
        out.name = (have_base ? base->name : std::string("white")) + "+" + mask.name;
        out.width = have_base ? base->width : mask.width;
        out.height = have_base ? base->height : mask.height;
        out.channels = 4;
        out.encoding = TextureEncoding::Srgb8;
        budgeted_resize(out.texels8, size_t(out.width) * size_t(out.height) * 4, "texture '" + out.name + "'");
        const int mask_channel = (mask.channels == 2 || mask.channels == 4) ? mask.channels - 1 : 0;
        for (int y = 0; y < out.height; ++y) {
            const int my = int(int64_t(y) * mask.height / out.height);
            for (int x = 0; x < out.width; ++x) {
                const int mx = int(int64_t(x) * mask.width / out.width);
                uint8_t* dst = &out.texels8[(size_t(y) * out.width + x) * 4];
                if (have_base) {
                    const uint8_t* src = &base->texels8[(size_t(y) * base->width + x) * base->channels];
                    for (int c = 0; c < 3; ++c) dst[c] = src[base->channels >= 3 ? c : 0];
                } else {
                    dst[0] = dst[1] = dst[2] = 255;
                }
                const size_t m = (size_t(my) * mask.width + mx) * mask.channels + mask_channel;
                dst[3] = mask.encoding == TextureEncoding::LinearFloat
                             ? uint8_t(std::clamp(mask.texels_f[m], 0.0f, 1.0f) * 255.0f + 0.5f)
                             : mask.texels8[m];
            }
        }
        return out;
    }

    bool enabled_;
    std::vector<std::string> paths_;
    std::map<std::string, size_t> slot_;
    std::vector<std::optional<Texture>> decoded_;
    std::set<std::string> missing_;
    std::map<std::pair<std::string, TextureEncoding>, int32_t> scene_index_;
};

// A bump map is used as a normal map only when it looks like one: tangent-space
// normal maps are bluish (z up) with red close to green; height maps are gray.
bool looks_like_normal_map(const Texture& t) {
    if (t.channels < 3 || t.encoding == TextureEncoding::LinearFloat || t.texels8.empty()) return false;
    const size_t texels = size_t(t.width) * t.height;
    const size_t step = std::max<size_t>(1, texels / 4096);
    double sum[3] = {0, 0, 0};
    size_t n = 0;
    for (size_t i = 0; i < texels; i += step, ++n)
        for (int c = 0; c < 3; ++c) sum[c] += t.texels8[i * t.channels + c];
    const double r = sum[0] / (255.0 * n), g = sum[1] / (255.0 * n), b = sum[2] / (255.0 * n);
    return b > 0.5 && b > std::max(r, g) + 0.15 && std::abs(r - g) < 0.1;
}

// Adds the used materials (in order of first use) and returns, for each
// usemtl name, its index in scene.materials.
std::vector<uint32_t> add_materials(Scene& scene, const std::string& obj_path,
                                    const std::vector<std::string>& used_materials,
                                    const std::vector<MaterialLibrary>& libraries, bool load_textures) {
    TextureTable textures(load_textures);
    std::vector<MaterialTextures> wanted(used_materials.size());
    std::vector<uint32_t> scene_index(used_materials.size());

    for (size_t i = 0; i < used_materials.size(); ++i) {
        const std::string& name = used_materials[i];
        const tinyobj::material_t* source = nullptr;
        const MaterialLibrary* library = nullptr;
        for (const MaterialLibrary& lib : libraries) {
            auto it = lib.by_name.find(name);
            if (it != lib.by_name.end()) {
                source = &lib.materials[size_t(it->second)];
                library = &lib;
                break;
            }
        }
        scene_index[i] = uint32_t(scene.materials.size());
        if (!source) {
            if (!libraries.empty()) warn(obj_path + ": material '" + name + "' is not defined; using a default");
            scene.materials.push_back(default_obj_material(name));
            continue;
        }
        const auto index = size_t(source - library->materials.data());
        const MtlStatements written = index < library->statements.size()
                                          ? library->statements[index]
                                          : MtlStatements{source->ior != 1.0, source->illum != 0};
        scene.materials.push_back(material_from_mtl(*source, written));
        MaterialTextures& t = wanted[i];
        t.base_color = textures.request(*library, source->diffuse_texname);
        t.mask = textures.request(*library, source->alpha_texname);
        t.emission = textures.request(*library, source->emissive_texname);
        if (!source->normal_texname.empty()) {
            t.normal = textures.request(*library, source->normal_texname);
        } else if (!source->bump_texname.empty()) {
            t.normal = textures.request(*library, source->bump_texname);
            t.normal_is_bump = true;
        }
    }

    textures.decode_all();
    for (size_t i = 0; i < wanted.size(); ++i) {
        Material& m = scene.materials[scene_index[i]];
        const MaterialTextures& t = wanted[i];
        if (!t.mask.empty() && textures.decoded(t.mask)) {
            m.base_color_texture = textures.masked_texture(scene, t.base_color, t.mask);
            m.alpha_mode = AlphaMode::Mask;
        } else if (!t.base_color.empty()) {
            m.base_color_texture = textures.scene_texture(scene, t.base_color, TextureEncoding::Srgb8);
        }
        // A texture replaces the color (MTL multiplies by Kd, but exporters write Kd = 0.588 gray).
        if (m.base_color_texture != kNoTexture && m.metallic == 0.0f && m.transmission == 0.0f)
            m.base_color = Vec3f{1.0f, 1.0f, 1.0f};
        if (!t.emission.empty()) {
            m.emission_texture = textures.scene_texture(scene, t.emission, TextureEncoding::Srgb8);
            if (m.emission_texture != kNoTexture && max_component(m.emission) <= 0.0f) m.emission = Vec3f{1, 1, 1};
        }
        if (!t.normal.empty()) {
            const Texture* decoded = textures.decoded(t.normal);
            if (decoded && (!t.normal_is_bump || looks_like_normal_map(*decoded)))
                m.normal_texture = textures.scene_texture(scene, t.normal, TextureEncoding::Linear8);
        }
    }
    return scene_index;
}

}  // namespace

namespace io {

Material default_obj_material(const std::string& name) {
    // MTL's defaults have no specular: a grey Lambertian.
    Material m;
    m.name = name;
    m.specular = 0.0f;
    return m;
}

std::vector<uint32_t> add_obj_materials(Scene& scene, const std::string& obj_path,
                                        const std::vector<std::string>& used_materials,
                                        const std::vector<std::string>& libraries, bool load_textures) {
    return add_materials(scene, obj_path, used_materials, load_material_libraries(obj_path, libraries), load_textures);
}

}  // namespace io

Scene load_obj(const std::string& path, const LoadOptions& options) {
    ObjGeometry geo(path);
    io::ObjParser<ObjGeometry> parser(path, geo);
    parser.lines(io::MappedFile(path).bytes());
    parser.finish();
    if (geo.corners.empty()) throw file_error(path, 0, "no faces");
    if (parser.skipped_faces() > 0)
        warn(path + ": skipped " + std::to_string(parser.skipped_faces()) + " faces with fewer than 3 vertices");
    checked_index_count(path + ": OBJ triangle count", geo.corners.size() / 3);

    Scene scene;
    scene.source = path;
    std::vector<uint32_t> material_index =
        io::add_obj_materials(scene, path, parser.used_materials(), parser.libraries(), options.load_textures);

    // Triangles before any usemtl get a default material.
    std::vector<uint32_t> triangle_material(geo.triangle_material.size());
    uint32_t default_material = kAbsent;
    for (size_t t = 0; t < triangle_material.size(); ++t) {
        uint32_t used = geo.triangle_material[t];
        if (used == kAbsent) {
            if (default_material == kAbsent) {
                default_material = uint32_t(scene.materials.size());
                scene.materials.push_back(default_obj_material("default"));
            }
            triangle_material[t] = default_material;
        } else {
            triangle_material[t] = material_index[used];
        }
    }
    geo.triangle_material.clear();
    geo.triangle_material.shrink_to_fit();

    Mesh mesh = build_mesh(path, geo, triangle_material, options.compute_missing_normals);
    mesh.name = std::filesystem::path(path).stem().string();
    scene.meshes.push_back(std::move(mesh));
    scene.finalize();
    return scene;
}

}  // namespace rf
