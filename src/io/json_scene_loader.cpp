// The JSON scene format (docs/scene-format.md): a list of mesh files or
// built-in scenes, each placed by a transform and optionally given a named
// material, plus materials, camera, lights, environment and render settings.
// Referenced files are loaded with rf::load_scene and merged (meshes,
// materials and textures re-indexed, instances composed with the transform).
// The reader is strict: an unknown key or a value of the wrong type is an
// error naming its JSON path, so typos do not silently change a scene.
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "io/procedural_sky.h"
#include "scene/animation_eval.h"

namespace rf {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr float kPi = 3.14159265358979f;
constexpr int kMaxNesting = 8;

float radians(float degrees) { return degrees * kPi / 180.0f; }

// fs::is_regular_file without the throwing overload's filesystem_error (file
// names too long, permission denied on a parent): such a file is not found.
bool is_regular_file(const std::string& path) {
    std::error_code ec;
    return fs::is_regular_file(path, ec);
}

// Scene files may include scene files: the files being read, outermost
// first, to report a file that includes itself.
thread_local std::vector<std::string> g_open_scene_files;

class JsonSceneReader {
public:
    JsonSceneReader(const std::string& path, const LoadOptions& options)
        : path_(path), dir_(fs::path(path).parent_path()), options_(options) {}

    Scene read(const Json& root);

private:
    [[noreturn]] void fail(const std::string& where, const std::string& reason) const {
        throw file_error(path_, 0, where + ": " + reason);
    }

    // Type-checked access; `where` is the JSON path used in errors.
    void expect_keys(const Json& object, const std::string& where,
                     std::initializer_list<const char*> allowed) const;
    const Json& expect_object(const Json& value, const std::string& where) const;
    float number(const Json& value, const std::string& where) const;
    int integer(const Json& value, const std::string& where, int min_value) const;
    std::string string(const Json& value, const std::string& where) const;
    Vec3f vec3(const Json& value, const std::string& where) const;

    std::string resolve(const std::string& relative) const;
    int32_t load_texture_file(const Json& value, const std::string& where, TextureEncoding encoding,
                              Scene& scene) const;

    Affine3f transform(const Json& value, const std::string& where) const;
    AnimatedNode animation(const Json& value, const std::string& where) const;
    Vec4f rotation_key(const Json& value, const std::string& where) const;
    Material material(const std::string& name, const Json& value, const std::string& where,
                      Scene& scene) const;
    void read_materials(const Json& value, Scene& scene);
    bool two_sided_emission(const Json& value, const std::string& where) const;
    void read_mesh_entry(const Json& value, const std::string& where, Scene& scene);
    Camera camera(const Json& value, const std::string& where) const;
    Light light(const Json& value, const std::string& where) const;
    void read_environment(const Json& value, const std::string& where, Scene& scene) const;
    RenderSettings render_settings(const Json& value, const std::string& where) const;

    // A loaded file, kept so that repeated references add instances only.
    struct LoadedPart {
        uint32_t first_mesh = 0;
        std::vector<Instance> instances;  // of the part, with mesh indices already offset
        std::vector<Light> lights;
        std::optional<Camera> camera;
        // The part's own animation (mesh indices offset; node indices the
        // part's): its nodes are copied at each placement, its deformations
        // (vertex keyframes, morphs, skins) were merged once with the meshes.
        std::vector<AnimatedNode> nodes;
        std::vector<InstanceAnimation> instance_animations;  // instance: index into `instances`
        std::vector<uint32_t> skin_joints_base;  // per merged skin: where its joints point (the first placement)
        std::vector<size_t> merged_skins;        // indices into Scene::animation::skins
        std::vector<uint8_t> skinned;            // per instance: its mesh is skinned (world space already)
        int placements = 0;
    };
    LoadedPart& load_part(const std::string& file_value, const std::string& material_name, int64_t override_material,
                          const std::string& where, Scene& scene);
    void place_instances(LoadedPart& part, const Affine3f& placement, int32_t keys_node, Scene& scene,
                         const std::string& where) const;
    void place_lights_and_camera(const LoadedPart& part, const Affine3f& placement, Scene& scene) const;
    void take_part_animation(Scene& part, LoadedPart& loaded, Scene& scene);
    void place_part_animation(LoadedPart& part, const Affine3f& placement, int32_t keys_node, Scene& scene,
                              const std::string& where, std::vector<int32_t>& instance_nodes,
                              std::vector<Affine3f>& instance_locals) const;

    // The time the animation covers: the entries' keys and the referenced files' own ranges.
    std::optional<std::pair<float, float>> time_range_;
    bool has_part_animation_ = false;
    void cover(float start, float end) {
        time_range_ = time_range_ ? std::make_pair(std::min(time_range_->first, start), std::max(time_range_->second, end))
                                  : std::make_pair(start, end);
    }

    const std::string path_;
    const fs::path dir_;
    const LoadOptions& options_;
    std::map<std::string, uint32_t> named_materials_;           // name -> Scene::materials index
    std::map<std::pair<std::string, std::string>, LoadedPart> parts_;  // (file, material) -> part
};

std::string type_name(const Json& value) { return value.type_name(); }

void JsonSceneReader::expect_keys(const Json& object, const std::string& where,
                                  std::initializer_list<const char*> allowed) const {
    for (const auto& item : object.items()) {
        bool known = false;
        for (const char* key : allowed) known = known || item.key() == key;
        if (!known) {
            std::string list;
            for (const char* key : allowed) list += (list.empty() ? "" : ", ") + std::string(key);
            fail(where.empty() ? item.key() : where + "." + item.key(),
                 "unknown key (expected one of: " + list + ")");
        }
    }
}

const Json& JsonSceneReader::expect_object(const Json& value, const std::string& where) const {
    if (!value.is_object()) fail(where, "expected an object, got " + type_name(value));
    return value;
}

float JsonSceneReader::number(const Json& value, const std::string& where) const {
    if (!value.is_number()) fail(where, "expected a number, got " + type_name(value));
    const double v = value.get<double>();
    if (!std::isfinite(v) || std::fabs(v) > 3.0e38) fail(where, "number out of range");
    return float(v);
}

int JsonSceneReader::integer(const Json& value, const std::string& where, int min_value) const {
    if (!value.is_number_integer()) fail(where, "expected an integer, got " + type_name(value));
    const auto v = value.get<long long>();
    if (v < min_value || v > 1000000000LL)
        fail(where, "expected an integer in [" + std::to_string(min_value) + ", 1000000000]");
    return int(v);
}

std::string JsonSceneReader::string(const Json& value, const std::string& where) const {
    if (!value.is_string()) fail(where, "expected a string, got " + type_name(value));
    return value.get<std::string>();
}

Vec3f JsonSceneReader::vec3(const Json& value, const std::string& where) const {
    if (!value.is_array() || value.size() != 3) fail(where, "expected an array of 3 numbers");
    Vec3f v;
    for (int i = 0; i < 3; ++i) v[i] = number(value[size_t(i)], where + "[" + std::to_string(i) + "]");
    return v;
}

std::string JsonSceneReader::resolve(const std::string& relative) const {
    fs::path p(relative);
    return p.is_absolute() ? p.string() : (dir_ / p).string();
}

int32_t JsonSceneReader::load_texture_file(const Json& value, const std::string& where,
                                           TextureEncoding encoding, Scene& scene) const {
    const std::string file = resolve(string(value, where));
    if (!options_.load_textures) return kNoTexture;
    if (!is_regular_file(file)) fail(where, "texture file '" + file + "' not found");
    try {
        scene.textures.push_back(load_texture(file, encoding));
    } catch (const Error& e) {
        fail(where, e.what());
    }
    return int32_t(scene.textures.size() - 1);
}

// {"translate": [x,y,z], "rotate": {"axis": [x,y,z], "degrees": d}, "scale": s or [x,y,z]}
// applied as scale, then rotate, then translate; or {"matrix": [16 numbers, column-major]}.
Affine3f JsonSceneReader::transform(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where, {"translate", "rotate", "scale", "matrix"});
    if (value.contains("matrix")) {
        if (value.size() != 1) fail(where, "\"matrix\" cannot be combined with translate, rotate or scale");
        const Json& m = value["matrix"];
        if (!m.is_array() || m.size() != 16) fail(where + ".matrix", "expected an array of 16 numbers");
        double column_major[16];
        for (size_t i = 0; i < 16; ++i)
            column_major[i] = number(m[i], where + ".matrix[" + std::to_string(i) + "]");
        return Affine3f::from_column_major(column_major);
    }
    Affine3f t, r, s;
    if (value.contains("translate")) t = Affine3f::translation(vec3(value["translate"], where + ".translate"));
    if (value.contains("rotate")) {
        const std::string w = where + ".rotate";
        const Json& rotate = expect_object(value["rotate"], w);
        expect_keys(rotate, w, {"axis", "degrees"});
        if (!rotate.contains("axis") || !rotate.contains("degrees"))
            fail(w, "expected {\"axis\": [x, y, z], \"degrees\": number}");
        Vec3f axis = vec3(rotate["axis"], w + ".axis");
        if (!(length(axis) > 0.0f)) fail(w + ".axis", "axis must not be zero");
        r = Affine3f::rotation(normalize(axis), radians(number(rotate["degrees"], w + ".degrees")));
    }
    if (value.contains("scale")) {
        const Json& scale = value["scale"];
        const std::string w = where + ".scale";
        Vec3f v;
        if (scale.is_number()) v = Vec3f(number(scale, w));
        else if (scale.is_array() && scale.size() == 3 &&
                 scale[0].is_number() && scale[1].is_number() && scale[2].is_number())
            v = vec3(scale, w);
        else fail(w, "expected a number or an array of 3 numbers");
        if (v.x == 0.0f || v.y == 0.0f || v.z == 0.0f) fail(w, "scale must not be zero");
        s = Affine3f::scale(v);
    }
    return t * r * s;
}

// {"axis": [x,y,z], "degrees": d} or {"quaternion": [x,y,z,w]}: a unit quaternion.
Vec4f JsonSceneReader::rotation_key(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where, {"axis", "degrees", "quaternion"});
    if (value.contains("quaternion")) {
        const Json& q = value["quaternion"];
        if (value.size() != 1 || !q.is_array() || q.size() != 4) fail(where, "expected {\"quaternion\": [x, y, z, w]}");
        Vec4f r;
        float* c[4] = {&r.x, &r.y, &r.z, &r.w};
        for (size_t i = 0; i < 4; ++i) *c[i] = number(q[i], where + ".quaternion[" + std::to_string(i) + "]");
        const float n = std::sqrt(r.x * r.x + r.y * r.y + r.z * r.z + r.w * r.w);
        if (!(n > 0.0f) || !std::isfinite(n)) fail(where + ".quaternion", "must not be zero");
        return Vec4f{r.x / n, r.y / n, r.z / n, r.w / n};
    }
    if (!value.contains("axis") || !value.contains("degrees")) fail(where, "expected {\"axis\": [x, y, z], \"degrees\": number}");
    const Vec3f axis = vec3(value["axis"], where + ".axis");
    if (!(length(axis) > 0.0f)) fail(where + ".axis", "axis must not be zero");
    return axis_angle_quaternion(axis.x, axis.y, axis.z, radians(number(value["degrees"], where + ".degrees")));
}

// {"interpolation": "linear" | "step", "keys": [{"time": t, "translate": [..], "rotate": {..}, "scale": s or [..]}, ...]}:
// a node whose translation, rotation and scale tracks take the keys that give them.
AnimatedNode JsonSceneReader::animation(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where, {"interpolation", "keys"});
    Interpolation interp = Interpolation::Linear;
    if (value.contains("interpolation")) {
        const std::string name = string(value["interpolation"], where + ".interpolation");
        if (name == "step") interp = Interpolation::Step;
        else if (name != "linear") fail(where + ".interpolation", "expected \"linear\" or \"step\"");
    }
    const Json& keys = value.contains("keys") ? value["keys"] : Json();
    if (!keys.is_array() || keys.empty()) fail(where + ".keys", "expected a non-empty array of keys");
    AnimatedNode node;
    Track* tracks[3] = {&node.translation_track, &node.rotation_track, &node.scale_track};
    for (Track* t : tracks) t->interpolation = interp;
    node.rotation_track.width = 4;
    for (size_t i = 0; i < keys.size(); ++i) {
        const std::string w = where + ".keys[" + std::to_string(i) + "]";
        expect_object(keys[i], w);
        expect_keys(keys[i], w, {"time", "translate", "rotate", "scale"});
        if (!keys[i].contains("time")) fail(w, "missing \"time\"");
        const float time = number(keys[i]["time"], w + ".time");
        const char* names[3] = {"translate", "rotate", "scale"};
        for (int k = 0; k < 3; ++k) {
            if (!keys[i].contains(names[k])) continue;
            Track& t = *tracks[k];
            if (!t.times.empty() && !(time > t.times.back())) fail(w + ".time", "times must increase");
            t.times.push_back(time);
            const Json& v = keys[i][names[k]];
            const std::string vw = w + "." + names[k];
            if (k == 1) {
                const Vec4f q = rotation_key(v, vw);
                t.values.insert(t.values.end(), {q.x, q.y, q.z, q.w});
                continue;
            }
            const Vec3f x = k == 2 && v.is_number() ? Vec3f(number(v, vw)) : vec3(v, vw);
            if (k == 2 && (x.x == 0.0f || x.y == 0.0f || x.z == 0.0f)) fail(vw, "scale must not be zero");
            t.values.insert(t.values.end(), {x.x, x.y, x.z});
        }
    }
    return node;
}

// "two_sided_emission", or its older name "double_sided"; false (front face
// only) when neither is given.
bool JsonSceneReader::two_sided_emission(const Json& value, const std::string& where) const {
    std::optional<bool> result;
    for (const char* key : {"two_sided_emission", "double_sided"}) {
        if (!value.contains(key)) continue;
        if (!value[key].is_boolean()) fail(where + "." + key, "expected true or false");
        const bool b = value[key].get<bool>();
        if (result && *result != b) fail(where + ".double_sided", "disagrees with two_sided_emission (same meaning)");
        result = b;
    }
    return result.value_or(false);
}

Material JsonSceneReader::material(const std::string& name, const Json& value, const std::string& where,
                                   Scene& scene) const {
    expect_object(value, where);
    expect_keys(value, where,
                {"base_color", "alpha", "metallic", "roughness", "emission", "emission_strength",
                 "transmission", "ior", "specular", "specular_color", "two_sided_emission", "double_sided",
                 "alpha_mode", "alpha_cutoff", "normal_scale",
                 "base_color_texture", "metallic_roughness_texture", "normal_texture",
                 "emission_texture", "ambient"});
    Material m;
    m.name = name;
    auto unit = [&](const char* key, float& out) {
        if (!value.contains(key)) return;
        out = number(value[key], where + "." + key);
        if (out < 0.0f || out > 1.0f) fail(where + "." + key, "expected a number in [0, 1]");
    };
    if (value.contains("base_color")) m.base_color = vec3(value["base_color"], where + ".base_color");
    unit("alpha", m.alpha);
    unit("metallic", m.metallic);
    unit("roughness", m.roughness);
    unit("transmission", m.transmission);
    unit("alpha_cutoff", m.alpha_cutoff);
    unit("specular", m.specular);
    if (value.contains("specular_color")) {
        m.specular_color = vec3(value["specular_color"], where + ".specular_color");
        if (min_component(m.specular_color) < 0.0f || max_component(m.specular_color) > 1.0f)
            fail(where + ".specular_color", "expected 3 numbers in [0, 1]");
    }
    if (value.contains("emission")) m.emission = vec3(value["emission"], where + ".emission");
    if (value.contains("ambient")) {
        m.ambient = vec3(value["ambient"], where + ".ambient");
        if (min_component(m.ambient) < 0.0f) fail(where + ".ambient", "expected 3 numbers, none negative");
    }
    if (value.contains("emission_strength")) {
        m.emission_strength = number(value["emission_strength"], where + ".emission_strength");
        if (m.emission_strength < 0.0f) fail(where + ".emission_strength", "must not be negative");
    }
    if (value.contains("ior")) {
        m.ior = number(value["ior"], where + ".ior");
        if (m.ior < 1.0f) fail(where + ".ior", "expected a number >= 1");
    }
    if (value.contains("normal_scale")) m.normal_scale = number(value["normal_scale"], where + ".normal_scale");
    m.two_sided_emission = two_sided_emission(value, where);
    if (value.contains("alpha_mode")) {
        const std::string mode = string(value["alpha_mode"], where + ".alpha_mode");
        if (mode == "opaque") m.alpha_mode = AlphaMode::Opaque;
        else if (mode == "mask") m.alpha_mode = AlphaMode::Mask;
        else if (mode == "blend") m.alpha_mode = AlphaMode::Blend;
        else fail(where + ".alpha_mode", "expected \"opaque\", \"mask\" or \"blend\"");
    }
    auto texture = [&](const char* key, TextureEncoding encoding, int32_t& out) {
        if (value.contains(key)) out = load_texture_file(value[key], where + "." + key, encoding, scene);
    };
    texture("base_color_texture", TextureEncoding::Srgb8, m.base_color_texture);
    texture("metallic_roughness_texture", TextureEncoding::Linear8, m.metallic_roughness_texture);
    texture("normal_texture", TextureEncoding::Linear8, m.normal_texture);
    texture("emission_texture", TextureEncoding::Srgb8, m.emission_texture);
    return m;
}

void JsonSceneReader::read_materials(const Json& value, Scene& scene) {
    expect_object(value, "materials");
    for (const auto& item : value.items()) {
        const std::string where = "materials." + item.key();
        named_materials_[item.key()] = uint32_t(scene.materials.size());
        Material m = material(item.key(), item.value(), where, scene);
        scene.materials.push_back(std::move(m));
    }
}

// Appends `part`'s meshes, materials and textures to `scene`, re-indexed.
// With `override_material` >= 0 every triangle gets that material instead.
void merge_into(Scene& scene, Scene&& part, int64_t override_material) {
    const auto material_offset = uint32_t(scene.materials.size());
    const auto texture_offset = int32_t(scene.textures.size());
    if (override_material < 0) {
        for (Material& m : part.materials) {
            for (int32_t* t : {&m.base_color_texture, &m.metallic_roughness_texture, &m.normal_texture,
                               &m.emission_texture})
                if (*t != kNoTexture) *t += texture_offset;
            scene.materials.push_back(std::move(m));
        }
        for (Texture& t : part.textures) scene.textures.push_back(std::move(t));
    }
    for (Mesh& mesh : part.meshes) {
        for (uint32_t& id : mesh.material_ids)
            id = override_material >= 0 ? uint32_t(override_material) : id + material_offset;
        scene.meshes.push_back(std::move(mesh));
    }
}

// A referenced file's animation joins the scene's. Deformations go in once,
// with the meshes (indices offset), and the meshes go in at rest (the scene
// evaluates them from there); nodes and instance animations are copied at
// each placement (place_part_animation). Its camera path is not followed.
void JsonSceneReader::take_part_animation(Scene& part, LoadedPart& loaded, Scene& scene) {
    Animation& from = part.animation;
    Animation& to = scene.animation;
    const uint32_t offset = loaded.first_mesh;
    to.rest_positions.resize(offset);
    to.rest_normals.resize(offset);
    for (uint32_t m = 0; m < part.meshes.size(); ++m) {
        const bool rest = m < from.rest_positions.size() && !from.rest_positions[m].empty();
        to.rest_positions.push_back(rest ? from.rest_positions[m] : std::vector<Vec3f>{});
        to.rest_normals.push_back(rest && m < from.rest_normals.size() ? from.rest_normals[m] : std::vector<Vec3f>{});
    }
    for (VertexKeyframes& k : from.vertex_keyframes) {
        k.mesh += offset;
        to.vertex_keyframes.push_back(std::move(k));
    }
    for (MorphTargets& m : from.morphs) {
        m.mesh += offset;
        to.morphs.push_back(std::move(m));
    }
    std::vector<uint8_t> skinned_mesh(part.meshes.size(), 0);
    for (Skin& s : from.skins) {  // joints are fixed at the first placement
        if (s.mesh < skinned_mesh.size()) skinned_mesh[s.mesh] = 1;
        s.mesh += offset;
        loaded.merged_skins.push_back(to.skins.size());
        to.skins.push_back(std::move(s));
    }
    for (const Instance& inst : part.instances)
        loaded.skinned.push_back(inst.mesh < skinned_mesh.size() ? skinned_mesh[inst.mesh] : 0);
    loaded.nodes = from.nodes;
    loaded.instance_animations = from.instances;
    if (!has_part_animation_) to.frames_per_second = from.frames_per_second;
    cover(from.start, from.end);
    has_part_animation_ = true;
}

// One placement of an animated part: a node for the placement (under the
// entry's own keys, when it has some), the part's nodes copied below it, and
// each instance's node and local transform. A skinned mesh's vertices are in
// world space already (its joints carry the placement); one mesh cannot be
// skinned at two placements, so a skinned part is placed once.
void JsonSceneReader::place_part_animation(LoadedPart& part, const Affine3f& placement, int32_t keys_node,
                                           Scene& scene, const std::string& where,
                                           std::vector<int32_t>& instance_nodes,
                                           std::vector<Affine3f>& instance_locals) const {
    if (!part.merged_skins.empty() && part.placements > 0)
        fail(where + ".file", "a skinned file can be placed once (its skin deforms the mesh every placement shares)");
    Animation& a = scene.animation;
    AnimatedNode place;
    place.name = "placement";
    place.parent = keys_node;
    place.matrix = placement;
    const auto place_index = int32_t(a.nodes.size());
    a.nodes.push_back(place);
    const auto base = int32_t(a.nodes.size());
    for (AnimatedNode node : part.nodes) {
        node.parent = node.parent < 0 ? place_index : node.parent + base;
        a.nodes.push_back(std::move(node));
    }
    for (const InstanceAnimation& ia : part.instance_animations) {
        if (ia.instance >= instance_nodes.size()) continue;
        instance_nodes[ia.instance] = int32_t(ia.node) + base;
        instance_locals[ia.instance] = ia.local;
    }
    for (size_t i = 0; i < part.skinned.size(); ++i)
        if (part.skinned[i]) instance_nodes[i] = -1;
    if (part.placements == 0)
        for (size_t k : part.merged_skins)
            for (uint32_t& joint : a.skins[k].joints) joint += uint32_t(base);
    ++part.placements;
}

void JsonSceneReader::read_mesh_entry(const Json& value, const std::string& where, Scene& scene) {
    expect_object(value, where);
    expect_keys(value, where, {"file", "transform", "material", "animation"});
    if (!value.contains("file")) fail(where, "missing \"file\"");
    const Affine3f placement = value.contains("transform") ? transform(value["transform"], where + ".transform")
                                                           : Affine3f::identity();
    std::string material_name;
    int64_t override_material = -1;
    if (value.contains("material")) {
        material_name = string(value["material"], where + ".material");
        auto it = named_materials_.find(material_name);
        if (it == named_materials_.end())
            fail(where + ".material", "no material named '" + material_name + "' in \"materials\"");
        override_material = it->second;
    }
    LoadedPart& part = load_part(string(value["file"], where + ".file"), material_name, override_material, where, scene);
    int32_t node = -1;
    if (value.contains("animation")) {
        node = int32_t(scene.animation.nodes.size());
        scene.animation.nodes.push_back(animation(value["animation"], where + ".animation"));
        const AnimatedNode& keys = scene.animation.nodes.back();
        for (const Track* t : {&keys.translation_track, &keys.rotation_track, &keys.scale_track})
            if (!t->empty()) cover(t->times.front(), t->times.back());
    }
    place_instances(part, placement, node, scene, where);
    place_lights_and_camera(part, placement, scene);
}

// The part a file (with a material override) makes, loaded and merged into
// the scene at its first mention; later mentions place the same meshes again.
JsonSceneReader::LoadedPart& JsonSceneReader::load_part(const std::string& file_value, const std::string& material_name,
                                                        int64_t override_material, const std::string& where,
                                                        Scene& scene) {
    const bool builtin = file_value.rfind("builtin:", 0) == 0;
    const std::string file = builtin ? file_value : resolve(file_value);
    auto it = parts_.find(std::make_pair(file, material_name));
    if (it != parts_.end()) return it->second;
    if (!builtin && !is_regular_file(file)) fail(where + ".file", "'" + file + "' not found");
    Scene part;
    try {
        part = load_scene(file, options_);
    } catch (const Error& e) {
        fail(where + ".file", e.what());
    }
    LoadedPart loaded;
    loaded.first_mesh = uint32_t(scene.meshes.size());
    loaded.instances = part.instances;
    for (Instance& instance : loaded.instances) instance.mesh += loaded.first_mesh;
    loaded.lights = part.lights;
    loaded.camera = part.camera;
    if (part.animated()) take_part_animation(part, loaded, scene);
    merge_into(scene, std::move(part), override_material);
    return parts_.emplace(std::make_pair(file, material_name), std::move(loaded)).first->second;
}

// The part's instances at one placement; `keys_node` (-1: none) is the
// entry's own keys, which move the placed part: world = keys(t) * placement * the part's own.
void JsonSceneReader::place_instances(LoadedPart& part, const Affine3f& placement, int32_t keys_node, Scene& scene,
                                      const std::string& where) const {
    // Per part instance: the node that moves it and the transform below that node (-1: still).
    std::vector<int32_t> instance_nodes(part.instances.size(), keys_node);
    std::vector<Affine3f> instance_locals(part.instances.size());
    for (size_t i = 0; i < part.instances.size(); ++i) instance_locals[i] = placement * part.instances[i].transform;
    if (!part.nodes.empty() || !part.merged_skins.empty())
        place_part_animation(part, placement, keys_node, scene, where, instance_nodes, instance_locals);
    for (size_t i = 0; i < part.instances.size(); ++i) {
        const Instance& instance = part.instances[i];
        if (instance_nodes[i] >= 0)  // world = node(t) * local
            scene.animation.instances.push_back(
                InstanceAnimation{uint32_t(scene.instances.size()), uint32_t(instance_nodes[i]), instance_locals[i]});
        const bool skinned = i < part.skinned.size() && part.skinned[i];
        const Affine3f still = skinned ? instance.transform : placement * instance.transform;
        scene.instances.push_back({instance.mesh, still, instance.visible});
    }
}

void JsonSceneReader::place_lights_and_camera(const LoadedPart& part, const Affine3f& placement, Scene& scene) const {
    for (Light light : part.lights) {
        light.position = placement.transform_point(light.position);
        Vec3f d = placement.transform_vector(light.direction);
        if (length(d) > 0.0f) light.direction = normalize(d);
        scene.lights.push_back(light);
    }
    // A camera in a referenced file is used only when the JSON file has none.
    if (part.camera && !scene.camera) {
        Camera c = *part.camera;
        c.eye = placement.transform_point(c.eye);
        c.target = placement.transform_point(c.target);
        c.up = normalize(placement.transform_vector(c.up));
        scene.camera = c;
    }
}

Camera JsonSceneReader::camera(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where, {"eye", "target", "up", "fov", "aperture", "focus_distance"});
    Camera c;
    if (value.contains("eye")) c.eye = vec3(value["eye"], where + ".eye");
    if (value.contains("target")) c.target = vec3(value["target"], where + ".target");
    if (value.contains("up")) c.up = vec3(value["up"], where + ".up");
    if (value.contains("fov")) {
        c.vfov_degrees = number(value["fov"], where + ".fov");
        if (!(c.vfov_degrees > 0.0f && c.vfov_degrees < 180.0f))
            fail(where + ".fov", "expected degrees in (0, 180)");
    }
    if (value.contains("aperture")) {
        c.aperture_radius = number(value["aperture"], where + ".aperture");
        if (c.aperture_radius < 0.0f) fail(where + ".aperture", "must not be negative");
    }
    if (value.contains("focus_distance")) {
        c.focus_distance = number(value["focus_distance"], where + ".focus_distance");
        if (c.focus_distance < 0.0f) fail(where + ".focus_distance", "must not be negative");
    }
    if (length(c.target - c.eye) == 0.0f) fail(where, "eye and target are the same point");
    return c;
}

Light JsonSceneReader::light(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where, {"type", "position", "direction", "color", "intensity", "inner_cone_deg",
                               "outer_cone_deg"});
    if (!value.contains("type")) fail(where, "missing \"type\" (point, spot or directional)");
    const std::string type = string(value["type"], where + ".type");
    Light light;
    if (type == "point") light.type = LightType::Point;
    else if (type == "spot") light.type = LightType::Spot;
    else if (type == "directional") light.type = LightType::Directional;
    else fail(where + ".type", "expected \"point\", \"spot\" or \"directional\", got \"" + type + "\"");
    if (value.contains("position")) light.position = vec3(value["position"], where + ".position");
    if (value.contains("direction")) {
        Vec3f d = vec3(value["direction"], where + ".direction");
        if (!(length(d) > 0.0f)) fail(where + ".direction", "must not be zero");
        light.direction = normalize(d);
    }
    if (value.contains("color")) light.color = vec3(value["color"], where + ".color");
    if (value.contains("intensity")) {
        light.intensity = number(value["intensity"], where + ".intensity");
        if (light.intensity < 0.0f) fail(where + ".intensity", "must not be negative");
    }
    if (value.contains("inner_cone_deg"))
        light.inner_cone_radians = radians(number(value["inner_cone_deg"], where + ".inner_cone_deg"));
    if (value.contains("outer_cone_deg"))
        light.outer_cone_radians = radians(number(value["outer_cone_deg"], where + ".outer_cone_deg"));
    if (light.inner_cone_radians < 0.0f || light.inner_cone_radians > light.outer_cone_radians ||
        light.outer_cone_radians > kPi * 0.5f)
        fail(where, "expected 0 <= inner_cone_deg <= outer_cone_deg <= 90");
    return light;
}

void JsonSceneReader::read_environment(const Json& value, const std::string& where, Scene& scene) const {
    expect_object(value, where);
    expect_keys(value, where, {"color", "map", "strength", "rotation_deg", "sun_elevation_deg", "sun_azimuth_deg"});
    Environment& env = scene.environment;
    if (value.contains("color")) env.color = vec3(value["color"], where + ".color");
    if (value.contains("strength")) {
        env.strength = number(value["strength"], where + ".strength");
        if (env.strength < 0.0f) fail(where + ".strength", "must not be negative");
    }
    if (value.contains("rotation_deg")) env.rotation_radians = radians(number(value["rotation_deg"], where + ".rotation_deg"));
    // "builtin:sky" is the procedural sky (io/procedural_sky.h), not a file;
    // only it takes the sun keys.
    const bool builtin_sky = value.contains("map") && value["map"].is_string() && value["map"] == "builtin:sky";
    for (const char* key : {"sun_elevation_deg", "sun_azimuth_deg"})
        if (value.contains(key) && !builtin_sky) fail(where + "." + key, "only allowed with \"map\": \"builtin:sky\"");
    if (builtin_sky) {
        float elevation = 35.0f, azimuth = 30.0f;
        if (value.contains("sun_elevation_deg")) {
            elevation = number(value["sun_elevation_deg"], where + ".sun_elevation_deg");
            if (!(elevation >= 1.0f && elevation <= 90.0f))
                fail(where + ".sun_elevation_deg", "must be in [1, 90]");
        }
        if (value.contains("sun_azimuth_deg")) azimuth = number(value["sun_azimuth_deg"], where + ".sun_azimuth_deg");
        if (options_.load_textures) {
            try {
                scene.textures.push_back(make_sky_texture(512, 256, elevation, azimuth));
            } catch (const Error& e) {
                fail(where + ".map", e.what());
            }
            env.texture = int32_t(scene.textures.size() - 1);
        }
    } else if (value.contains("map")) {
        env.texture = load_texture_file(value["map"], where + ".map", TextureEncoding::Srgb8, scene);
    }
}

RenderSettings JsonSceneReader::render_settings(const Json& value, const std::string& where) const {
    expect_object(value, where);
    expect_keys(value, where,
                {"width", "height", "spp", "integrator", "max_depth", "rr_depth", "light_sampling", "reflection_depth",
                 "refraction_depth", "shading", "ao_radius", "update"});
    RenderSettings r;
    if (value.contains("width")) r.width = integer(value["width"], where + ".width", 1);
    if (value.contains("height")) r.height = integer(value["height"], where + ".height", 1);
    if (value.contains("spp")) r.spp = integer(value["spp"], where + ".spp", 1);
    if (value.contains("max_depth")) r.max_depth = integer(value["max_depth"], where + ".max_depth", 0);
    if (value.contains("rr_depth")) r.rr_depth = integer(value["rr_depth"], where + ".rr_depth", 0);
    if (value.contains("reflection_depth"))
        r.reflection_depth = integer(value["reflection_depth"], where + ".reflection_depth", 0);
    if (value.contains("refraction_depth"))
        r.refraction_depth = integer(value["refraction_depth"], where + ".refraction_depth", 0);
    // Names are checked here so that a typo is reported with its JSON path.
    auto one_of = [&](const char* key, std::initializer_list<const char*> names) -> std::optional<std::string> {
        if (!value.contains(key)) return std::nullopt;
        std::string name = string(value[key], where + "." + key);
        std::string known;
        for (const char* n : names) {
            if (name == n) return name;
            known += (known.empty() ? "" : ", ") + std::string(n);
        }
        fail(where + "." + key, "unknown value '" + name + "' (expected " + known + ")");
        return std::nullopt;
    };
    r.integrator = one_of("integrator", {"normals", "ao", "whitted", "path"});
    r.light_sampling = one_of("light_sampling", {"mis", "nee", "bsdf"});
    r.shading = one_of("shading", {"lambert", "phong", "blinn"});
    r.update = one_of("update", {"refit", "adapt", "rebuild", "clusters", "two-level"});
    if (value.contains("ao_radius")) {
        r.ao_radius = number(value["ao_radius"], where + ".ao_radius");
        if (!(*r.ao_radius > 0.0f)) fail(where + ".ao_radius", "must be positive");
    }
    return r;
}

// The animation over [start, end]; the scene as at its start.
void start_animation(Scene& scene, std::pair<float, float> range) {
    Animation& a = scene.animation;
    a.start = range.first;
    a.end = range.second;
    scene.set_time(a.start);
    a.evaluated = false;  // the caller's first set_time reports everything animated
}

Scene JsonSceneReader::read(const Json& root) {
    if (!root.is_object()) throw file_error(path_, 0, "expected a JSON object at the top level");
    expect_keys(root, "", {"description", "meshes", "materials", "camera", "lights", "environment", "render"});
    Scene scene;
    scene.source = path_;
    if (root.contains("description")) string(root["description"], "description");
    // Materials first: mesh entries refer to them by name.
    if (root.contains("materials")) read_materials(root["materials"], scene);
    if (root.contains("camera")) scene.camera = camera(root["camera"], "camera");
    if (root.contains("meshes")) {
        const Json& meshes = root["meshes"];
        if (!meshes.is_array()) fail("meshes", "expected an array, got " + type_name(meshes));
        for (size_t i = 0; i < meshes.size(); ++i)
            read_mesh_entry(meshes[i], "meshes[" + std::to_string(i) + "]", scene);
    }
    if (root.contains("lights")) {
        const Json& lights = root["lights"];
        if (!lights.is_array()) fail("lights", "expected an array, got " + type_name(lights));
        for (size_t i = 0; i < lights.size(); ++i)
            scene.lights.push_back(light(lights[i], "lights[" + std::to_string(i) + "]"));
    }
    if (root.contains("environment")) read_environment(root["environment"], "environment", scene);
    if (root.contains("render")) scene.render_settings = render_settings(root["render"], "render");
    if (time_range_) start_animation(scene, *time_range_);
    return scene;
}

// "[json.exception.parse_error.101] parse error at line 2, column 3: ..." -> "parse error at line 2, ..."
std::string parse_error_reason(const std::string& what) {
    std::string reason = what;
    if (!reason.empty() && reason.front() == '[') {
        size_t close = reason.find("] ");
        if (close != std::string::npos) reason = reason.substr(close + 2);
    }
    for (char& c : reason)
        if (c == '\n' || c == '\r') c = ' ';
    return reason;
}

}  // namespace

Scene load_json_scene(const std::string& path, const LoadOptions& options) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw file_error(path, 0, "cannot open file");
    Json root;
    try {
        root = Json::parse(in);
    } catch (const Json::parse_error& e) {
        throw file_byte_error(path, e.byte, parse_error_reason(e.what()));
    } catch (const Json::exception& e) {
        // Not only syntax errors: a number too large for a double ("1e999") is out_of_range.
        throw file_error(path, 0, parse_error_reason(e.what()));
    }
    std::error_code ec;
    std::string canonical = fs::weakly_canonical(path, ec).string();
    if (ec) canonical = path;
    for (const std::string& open : g_open_scene_files)
        if (open == canonical) throw file_error(path, 0, "the file includes itself");
    if (g_open_scene_files.size() >= size_t(kMaxNesting))
        throw file_error(path, 0, "scene files nest more than " + std::to_string(kMaxNesting) + " levels deep");
    struct OpenFileGuard {
        explicit OpenFileGuard(const std::string& file) { g_open_scene_files.push_back(file); }
        ~OpenFileGuard() { g_open_scene_files.pop_back(); }
    } guard(canonical);
    Scene scene = JsonSceneReader(path, options).read(root);
    try {
        scene.finalize();
    } catch (const Error& e) {
        throw file_error(path, 0, e.what());
    }
    return scene;
}

}  // namespace rf
