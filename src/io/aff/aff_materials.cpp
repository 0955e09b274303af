// AFF materials: the NFF `f` and AFF `fm` lines, their mapping onto rf's
// metallic-roughness Material (one per definition and texture), and the
// texture files (found next to the file or in TextureFiles/, decoded at the end).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "io/aff/aff_parser.h"
#include "io/path_utils.h"
#include "io/phong_material.h"
#include "io/texture_batch.h"

namespace rf::io::aff {

namespace {

namespace fs = std::filesystem;

Vec3f clamp01(Vec3f c) { return {std::clamp(c.x, 0.0f, 1.0f), std::clamp(c.y, 0.0f, 1.0f), std::clamp(c.z, 0.0f, 1.0f)}; }

// Phong-era values onto the material model by the rules MTL follows
// (io/phong_material.h): diffuse is the base colour; Ks = 0 leaves a pure
// Lambertian, Ks > 0 a specular layer of that strength and width Shine; a
// strong Ks that dominates the diffuse is a mirror-like metal (NFF's Ks is
// also its ray-traced reflection); transmittance T > 0 is smooth glass with
// that transmission and index (an index < 1 is not one: 1.5).
void convert_definition(const MaterialDef& d, Material& m) {
    m.base_color = d.diffuse;
    m.ambient = d.ambient;  // times the am light in add_materials_and_settings
    if (d.transmittance > 0.0f) {
        m.transmission = std::clamp(d.transmittance, 0.0f, 1.0f);
        m.base_color = Vec3f{1, 1, 1};
        m.roughness = 0.0f;
        if (d.ior >= 1.0f) m.ior = d.ior;
    } else if (io::phong_mirror(d.diffuse, d.specular)) {
        io::set_phong_mirror(d.specular, d.shine, m);
    } else {
        io::set_phong_specular(d.specular, d.shine, m);
    }
}

}  // namespace

// Equal definitions share one index, so repeated `f` lines add no materials.
void AffParser::set_material(const MaterialDef& def) {
    auto [it, inserted] = material_defs_.try_emplace(def, uint32_t(material_defs_.size()));
    if (inserted) def_list_.push_back(def);
    current_def_ = int(it->second);
}

// NFF: f red green blue Kd Ks Shine T index_of_refraction
void AffParser::parse_nff_material() {
    const Vec3f color = in().read_vec3("material color");
    const float kd = in().read_float("material Kd");
    const float ks = in().read_float("material Ks");
    MaterialDef def;
    def.diffuse = clamp01(color * kd);
    def.specular = clamp01(Vec3f(ks));
    def.shine = in().read_float("material shine");
    def.transmittance = in().read_float("material transmittance");
    def.ior = in().read_float("material index of refraction");
    set_material(def);
}

// AFF: fm ambient(rgb) diffuse(rgb) specular(rgb) shine T index_of_refraction
void AffParser::parse_fm_material() {
    MaterialDef def;
    def.ambient = max(in().read_vec3("material ambient color"), Vec3f(0.0f));
    def.diffuse = clamp01(in().read_vec3("material diffuse color"));
    def.specular = clamp01(in().read_vec3("material specular color"));
    def.shine = in().read_float("material shine");
    def.transmittance = in().read_float("material transmittance");
    def.ior = in().read_float("material index of refraction");
    set_material(def);
}

uint32_t AffParser::material_index(const std::string& texture_name) {
    std::string texture;
    if (!texture_name.empty() && options_.load_textures) texture = find_texture(texture_name);
    const auto key = std::make_pair(current_def_, texture);
    auto it = material_index_.find(key);
    if (it != material_index_.end()) return it->second;
    const uint32_t index = uint32_t(materials_.size());
    Material m;
    if (current_def_ < 0) {
        m.name = "default";
        m.specular = 0.0f;  // no f line yet: a Lambertian, as an f line with Ks = 0
    } else {
        m.name = "aff" + std::to_string(current_def_);
        convert_definition(def_list_[size_t(current_def_)], m);
    }
    fallback_color_.push_back(m.base_color);
    if (!texture.empty()) {
        m.name += '+';  // two appends: GCC 12 reports a false -Wrestrict on "+" + string here
        m.name += fs::path(texture).filename().string();
        if (m.metallic == 0.0f && m.transmission == 0.0f) m.base_color = Vec3f{1, 1, 1};  // the map replaces the color
    }
    materials_.push_back(m);
    material_texture_.push_back(texture);
    material_index_.emplace(key, index);
    return index;
}

// A texture name: next to the file, in ../TextureFiles, or the same next to the root file.
std::string AffParser::find_texture(const std::string& name) {
    auto cached = texture_lookup_.find(name + "\n" + in().path());
    if (cached != texture_lookup_.end()) return cached->second;
    std::string found;
    for (const std::string& base : {in().path(), root_}) {
        for (const std::string& candidate : {name, "../TextureFiles/" + name, "TextureFiles/" + name}) {
            std::optional<std::string> f = io::find_file_case_insensitive(io::resolve_relative(base, candidate));
            if (f && fs::is_regular_file(*f)) {
                found = *f;
                break;
            }
        }
        if (!found.empty()) break;
    }
    if (found.empty() && missing_textures_.insert(name).second)
        warn(in().path() + ": texture '" + name + "' not found; using the material's color");
    texture_lookup_[name + "\n" + in().path()] = found;
    return found;
}

// Decodes each texture file once; a material whose map could not be read gets its color back.
void AffParser::attach_textures(Scene& scene) {
    std::vector<std::string> paths;
    std::map<std::string, size_t> slot;
    for (const std::string& p : material_texture_)
        if (!p.empty() && slot.emplace(p, paths.size()).second) paths.push_back(p);
    std::vector<std::optional<Texture>> decoded = decode_textures(paths, "the material's color");
    std::vector<int32_t> scene_index(paths.size(), kNoTexture);
    for (size_t m = 0; m < scene.materials.size() && m < material_texture_.size(); ++m) {
        const std::string& p = material_texture_[m];
        if (p.empty()) continue;
        const size_t s = slot.at(p);
        if (scene_index[s] == kNoTexture && decoded[s]) {
            scene.textures.push_back(std::move(*decoded[s]));
            decoded[s].reset();
            scene_index[s] = int32_t(scene.textures.size() - 1);
        }
        if (scene_index[s] != kNoTexture) {
            scene.materials[m].base_color_texture = scene_index[s];
        } else {
            scene.materials[m].base_color = fallback_color_[m];  // the map could not be read
        }
    }
}

}  // namespace rf::io::aff
