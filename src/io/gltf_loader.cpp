// glTF 2.0 loader (.gltf with external or data-URI buffers, and .glb), on
// top of tinygltf for the JSON and buffer plumbing. Everything tinygltf does
// not check (accessor and buffer-view ranges, index ranges, node cycles,
// finite coordinates) is validated here before any element is read.
//
// Mapping: each mesh primitive becomes one rf::Mesh, each node that
// references a mesh one rf::Instance per primitive with the node's world
// transform; the first camera node gives Scene::camera; KHR_lights_punctual
// nodes give Scene::lights. Images are kept encoded by tinygltf and decoded
// here, so the sRGB/linear choice follows the texture's use.
//
// Animation (Scene::animation): ONE animation of the file, the first unless
// LoadOptions::animation names another (files with several usually hold
// alternative clips: walk, run ...), its
// translation/rotation/scale channels as node tracks and its weights channels
// as morph weights; skins (linear blend, the 4 largest of JOINTS_0/1 weights,
// renormalised) and morph targets (POSITION/NORMAL deltas). Only the nodes
// needed become Animation::nodes: joints, nodes under an animated node that
// carry a mesh, and their ancestors (one parent per node, as glTF requires).
// A mesh that is skinned or morphed is converted once per node using it (its
// skin and weights belong to the node), and a skinned mesh's instance is the
// identity (glTF ignores the skinned node's transform). An animated scene is
// evaluated at its start time before it is returned. Cameras and lights do
// not follow animated nodes.
#include <tiny_gltf.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "io/file_reader.h"
#include "io/gltf_loader.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"

namespace rf {
namespace {

constexpr float kPi = 3.14159265358979f;

// tinygltf's messages are multi-line and may carry nlohmann-json's
// "[json.exception.parse_error.101] " tags; rf::Error messages are one line.
std::string one_line(std::string text) {
    for (size_t at; (at = text.find("[json.exception.")) != std::string::npos;) {
        size_t close = text.find("] ", at);
        if (close == std::string::npos) break;
        text.erase(at, close + 2 - at);
    }
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' '))
        text.pop_back();
    std::string out;
    out.reserve(text.size());
    for (char c : text) {
        if (c == '\n') out += "; ";
        else if (c != '\r') out += c;
    }
    return out;
}

void warn(const std::string& path, const std::string& message) {
    std::fprintf(stderr, "rayforge: warning: %s: %s\n", path.c_str(), message.c_str());
}

std::string lowercase_extension(const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

// --- Images -----------------------------------------------------------------

// tinygltf hands every image's encoded bytes to this callback. We keep them
// as they are (decoded later with the right encoding), after checking that a
// bufferView-backed image lies inside its buffer: tinygltf itself passes a
// pointer computed from unchecked offsets.
struct ImageLoaderContext {
    const tinygltf::Model* model = nullptr;
};

bool keep_encoded_image(tinygltf::Image* image, const int image_index, std::string* err,
                        std::string*, int, int, const unsigned char* bytes, int size,
                        void* user_data) {
    const auto* context = static_cast<const ImageLoaderContext*>(user_data);
    if (image->bufferView >= 0) {
        const tinygltf::Model& model = *context->model;
        const auto& view = model.bufferViews[size_t(image->bufferView)];  // index checked by tinygltf
        const auto& buffer = model.buffers[size_t(view.buffer)];
        if (view.byteOffset > buffer.data.size() ||
            view.byteLength > buffer.data.size() - view.byteOffset) {
            if (err)
                *err += "image " + std::to_string(image_index) +
                        ": bufferView lies outside its buffer\n";
            return false;
        }
    }
    if (size < 0) size = 0;
    image->image.assign(bytes, bytes + size);
    image->width = image->height = 0;  // marks "encoded, not decoded"
    return true;
}

// --- Files ------------------------------------------------------------------

// tinygltf's own file callbacks fopen() whatever a URI names: a FIFO or a
// device blocks or streams forever. These read regular files only, whole,
// with our one-line errors.
bool regular_file_exists(const std::string& path, void*) {
    std::error_code ec;  // the throwing overload throws for names that are too long
    return std::filesystem::is_regular_file(path, ec);
}

std::string unexpanded_path(const std::string& path, void*) { return path; }

bool read_regular_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
    try {
        const std::string bytes = io::read_file(path);
        out->assign(bytes.begin(), bytes.end());
        return true;
    } catch (const Error& e) {
        if (err) *err += std::string(e.what()) + "\n";
        return false;
    }
}

bool refuse_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
    if (err) *err += "writing is not supported\n";
    return false;
}

// --- Accessors --------------------------------------------------------------

size_t component_size(int component_type) {
    switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_INT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: return 8;
    default: return 0;
    }
}

int component_count(int type) {
    switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT2: return 4;
    case TINYGLTF_TYPE_MAT3: return 9;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
    }
}

// Reads one component as float, applying glTF's normalisation rules.
float read_component(const unsigned char* p, int component_type, bool normalized) {
    switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: { float v; std::memcpy(&v, p, 4); return v; }
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: { double v; std::memcpy(&v, p, 8); return float(v); }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
        float v = float(p[0]);
        return normalized ? v / 255.0f : v;
    }
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
        float v = float(static_cast<int8_t>(p[0]));
        return normalized ? std::max(v / 127.0f, -1.0f) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t v; std::memcpy(&v, p, 2);
        return normalized ? float(v) / 65535.0f : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t v; std::memcpy(&v, p, 2);
        return normalized ? std::max(float(v) / 32767.0f, -1.0f) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t v; std::memcpy(&v, p, 4);
        return normalized ? float(double(v) / 4294967295.0) : float(v);
    }
    case TINYGLTF_COMPONENT_TYPE_INT: {
        int32_t v; std::memcpy(&v, p, 4);
        return float(v);
    }
    default: return 0.0f;
    }
}

uint32_t read_index(const unsigned char* p, int component_type) {
    switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return p[0];
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t v; std::memcpy(&v, p, 2); return v; }
    default: { uint32_t v; std::memcpy(&v, p, 4); return v; }
    }
}

class GltfReader {
public:
    GltfReader(const std::string& path, const tinygltf::Model& model, const LoadOptions& options)
        : path_(path), model_(model), options_(options) {}

    Scene read();

private:
    [[noreturn]] void fail(const std::string& reason) const { throw file_error(path_, 0, reason); }

    // A validated view of an accessor's elements: element i starts at
    // data + i * stride.
    struct ElementView {
        const unsigned char* data = nullptr;
        size_t stride = 0;
        size_t count = 0;
        int component_type = 0;
        int components = 0;
        bool normalized = false;
    };
    ElementView element_view(int accessor_index, const char* what) const;
    std::vector<float> read_floats(int accessor_index, const char* what,
                                   std::initializer_list<int> allowed_types, int& components) const;
    std::vector<uint32_t> read_indices(int accessor_index) const;

    Affine3f local_transform(const tinygltf::Node& node, int node_index) const;
    void visit_node(int node_index, const Affine3f& parent, Scene& scene, int depth, bool animated);
    void add_instances(int node_index, const Affine3f& world, bool animated, Scene& scene);
    const std::vector<uint32_t>& mesh_primitives(int mesh_index, Scene& scene);
    bool convert_primitive(const tinygltf::Primitive& primitive, const std::string& name,
                           Scene& scene, Mesh& mesh);
    uint32_t material_index(int gltf_material, Scene& scene);
    void convert_materials(Scene& scene);
    void convert_specular(const tinygltf::ExtensionMap& extensions, Material& m);
    int32_t texture_index(int gltf_texture, TextureEncoding encoding, Scene& scene);
    void add_light(int light_index, const Affine3f& world, Scene& scene) const;
    void set_camera(int camera_index, const Affine3f& world, Scene& scene);

    // Animation: tracks of the first animation, skins, morph targets.
    struct NodeTracks {
        Track translation, rotation, scale;
    };
    enum class TrackKind { Translation, Rotation, Scale, Weights };
    void read_animation();
    [[nodiscard]] size_t chosen_animation() const;
    std::vector<std::string> clips_;  // every animation's name, when the file has any
    Track read_track(const tinygltf::Animation& animation, int sampler_index, TrackKind kind, int width,
                     const std::string& where) const;
    int32_t animated_node(int node_index, Scene& scene, int depth = 0);
    size_t morph_target_count(int mesh_index) const;
    const std::vector<uint32_t>& deformed_meshes(int node_index, Scene& scene);
    void add_morph_targets(const tinygltf::Primitive& primitive, int node_index, const std::string& name,
                           uint32_t mesh_id, size_t vertex_count, Scene& scene);
    std::vector<Vec3f> read_deltas(int accessor_index, const std::string& what, size_t vertex_count);
    void add_skin(int skin_index, const tinygltf::Primitive& primitive, const std::string& name, uint32_t mesh_id,
                  size_t vertex_count, Scene& scene);
    std::vector<float> read_skin_attribute(int accessor_index, const std::string& what, size_t vertex_count,
                                           bool joints) const;
    void read_influences(const tinygltf::Primitive& primitive, const std::string& name, size_t vertex_count,
                         Skin& skin) const;
    void finish_animation(Scene& scene) const;
    void account_animation(size_t count, size_t element_size);

    const std::string& path_;
    const tinygltf::Model& model_;
    const LoadOptions& options_;
    std::map<int, std::vector<uint32_t>> mesh_cache_;  // glTF mesh -> rf meshes (one per primitive)
    std::map<std::tuple<int, TextureEncoding>, int32_t> texture_cache_;
    std::vector<char> on_path_;      // nodes on the current root-to-node path (cycle check)
    size_t node_visits_ = 0;         // nodes visited so far, counting each time a shared node is reached
    int default_material_ = -1;      // appended for primitives without a material
    bool warned_non_triangles_ = false;
    bool warned_specular_textures_ = false;

    std::vector<int> node_parent_;           // glTF parent of each node (the first listed), -1 for roots
    std::vector<int32_t> animation_node_;    // glTF node -> Animation::nodes index, -1 when none yet
    std::map<int, NodeTracks> node_tracks_;  // glTF node -> its TRS tracks
    std::map<int, Track> weight_tracks_;     // glTF node -> its morph weights track
    std::map<std::pair<int, int>, std::vector<uint32_t>> deformed_cache_;  // (mesh, node) -> rf meshes
    // Bytes of the animation data so far (tracks, deformed copies of meshes,
    // morph deltas, skins): a sampler is read once per channel using it and a
    // deformed mesh copied once per node, so a small file could multiply them
    // past the budget in many allocations each under it
    // (tests/data/fuzz_repro/gltf_morph_targets_copied_per_node.gltf).
    size_t animation_bytes_ = 0;
    std::map<std::pair<int, size_t>, std::vector<Vec3f>> delta_cache_;  // (accessor, vertex count) -> deltas read
    float key_start_ = 0.0f, key_end_ = 0.0f;
    bool has_keys_ = false;
    bool warned_channel_path_ = false;
};

GltfReader::ElementView GltfReader::element_view(int accessor_index, const char* what) const {
    if (accessor_index < 0 || size_t(accessor_index) >= model_.accessors.size())
        fail(std::string(what) + ": accessor " + std::to_string(accessor_index) + " does not exist");
    const tinygltf::Accessor& accessor = model_.accessors[size_t(accessor_index)];
    const std::string where = std::string(what) + " accessor " + std::to_string(accessor_index);
    if (accessor.sparse.isSparse) fail(where + ": sparse accessors are not supported");

    ElementView view;
    view.count = accessor.count;
    view.component_type = accessor.componentType;
    view.components = component_count(accessor.type);
    view.normalized = accessor.normalized;
    const size_t csize = component_size(accessor.componentType);
    if (csize == 0 || view.components == 0) fail(where + ": invalid componentType or type");
    if (view.count > size_t(std::numeric_limits<uint32_t>::max()))
        fail(where + ": " + std::to_string(view.count) + " elements exceed the 2^32-1 limit");
    const size_t element_size = csize * size_t(view.components);
    // Without a bufferView an accessor is all zeros (meant for sparse
    // accessors); its count is backed by no data and could be anything.
    if (accessor.bufferView < 0) fail(where + ": accessors without a bufferView are not supported");

    if (size_t(accessor.bufferView) >= model_.bufferViews.size())
        fail(where + ": bufferView " + std::to_string(accessor.bufferView) + " does not exist");
    const tinygltf::BufferView& buffer_view = model_.bufferViews[size_t(accessor.bufferView)];
    if (buffer_view.buffer < 0 || size_t(buffer_view.buffer) >= model_.buffers.size())
        fail(where + ": buffer " + std::to_string(buffer_view.buffer) + " does not exist");
    const tinygltf::Buffer& buffer = model_.buffers[size_t(buffer_view.buffer)];
    if (buffer_view.byteOffset > buffer.data.size() ||
        buffer_view.byteLength > buffer.data.size() - buffer_view.byteOffset)
        fail(where + ": bufferView " + std::to_string(accessor.bufferView) + " (offset " +
             std::to_string(buffer_view.byteOffset) + ", length " +
             std::to_string(buffer_view.byteLength) + ") lies outside its buffer of " +
             std::to_string(buffer.data.size()) + " bytes");

    view.stride = buffer_view.byteStride != 0 ? buffer_view.byteStride : element_size;
    if (view.stride < element_size)
        fail(where + ": byteStride " + std::to_string(view.stride) + " is smaller than the element (" +
             std::to_string(element_size) + " bytes)");
    if (view.count > 0) {
        // offset + (count-1)*stride + element_size <= byteLength, without overflow.
        const size_t length = buffer_view.byteLength;
        const size_t offset = accessor.byteOffset;
        bool fits = offset <= length && element_size <= length - offset &&
                    (view.count - 1) <= (length - offset - element_size) / view.stride;
        if (!fits)
            fail(where + ": " + std::to_string(view.count) + " elements at offset " +
                 std::to_string(offset) + " (stride " + std::to_string(view.stride) +
                 ") exceed its bufferView of " + std::to_string(length) + " bytes");
    }
    view.data = buffer.data.data() + buffer_view.byteOffset + accessor.byteOffset;
    return view;
}

std::vector<float> GltfReader::read_floats(int accessor_index, const char* what,
                                           std::initializer_list<int> allowed_types,
                                           int& components) const {
    ElementView view = element_view(accessor_index, what);
    if (std::find(allowed_types.begin(), allowed_types.end(),
                  model_.accessors[size_t(accessor_index)].type) == allowed_types.end())
        fail(std::string(what) + " accessor " + std::to_string(accessor_index) +
             ": unexpected element type");
    components = view.components;
    std::vector<float> out;
    budgeted_resize(out, view.count * size_t(view.components),
                    path_ + ": " + what + " accessor " + std::to_string(accessor_index));
    const size_t csize = component_size(view.component_type);
    for (size_t i = 0; i < view.count; ++i) {
        const unsigned char* element = view.data + i * view.stride;
        for (int c = 0; c < view.components; ++c)
            out[i * size_t(view.components) + size_t(c)] =
                read_component(element + size_t(c) * csize, view.component_type, view.normalized);
    }
    return out;
}

std::vector<uint32_t> GltfReader::read_indices(int accessor_index) const {
    ElementView view = element_view(accessor_index, "indices");
    const auto& accessor = model_.accessors[size_t(accessor_index)];
    if (accessor.type != TINYGLTF_TYPE_SCALAR ||
        (view.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
         view.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
         view.component_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
        fail("indices accessor " + std::to_string(accessor_index) +
             ": indices must be unsigned byte, short or int scalars");
    std::vector<uint32_t> out;
    budgeted_resize(out, view.count, path_ + ": indices accessor " + std::to_string(accessor_index));
    for (size_t i = 0; i < view.count; ++i)
        out[i] = read_index(view.data + i * view.stride, view.component_type);
    return out;
}

// --- Materials and textures -------------------------------------------------

TextureWrap wrap_mode(int gl_wrap) {
    switch (gl_wrap) {
    case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE: return TextureWrap::ClampToEdge;
    case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT: return TextureWrap::MirroredRepeat;
    default: return TextureWrap::Repeat;
    }
}

int32_t GltfReader::texture_index(int gltf_texture, TextureEncoding encoding, Scene& scene) {
    if (gltf_texture < 0 || !options_.load_textures) return kNoTexture;
    if (size_t(gltf_texture) >= model_.textures.size())
        fail("texture " + std::to_string(gltf_texture) + " does not exist");
    auto key = std::make_tuple(gltf_texture, encoding);
    if (auto it = texture_cache_.find(key); it != texture_cache_.end()) return it->second;

    const tinygltf::Texture& gltf = model_.textures[size_t(gltf_texture)];
    if (gltf.source < 0 || size_t(gltf.source) >= model_.images.size())
        fail("texture " + std::to_string(gltf_texture) + ": image " + std::to_string(gltf.source) +
             " does not exist");
    const tinygltf::Image& image = model_.images[size_t(gltf.source)];
    std::string name;
    if (!image.uri.empty()) {
        name = (std::filesystem::path(path_).parent_path() / image.uri).string();
    } else {
        name = path_ + "#image" + std::to_string(gltf.source);
    }
    if (image.image.empty()) fail("image '" + (image.uri.empty() ? name : image.uri) + "' could not be read");

    Texture texture = load_texture_from_memory(image.image.data(), image.image.size(), name, encoding);
    if (gltf.sampler >= 0) {
        if (size_t(gltf.sampler) >= model_.samplers.size())
            fail("texture " + std::to_string(gltf_texture) + ": sampler " +
                 std::to_string(gltf.sampler) + " does not exist");
        const tinygltf::Sampler& sampler = model_.samplers[size_t(gltf.sampler)];
        texture.wrap_s = wrap_mode(sampler.wrapS);
        texture.wrap_t = wrap_mode(sampler.wrapT);
    }
    const auto index = int32_t(scene.textures.size());
    scene.textures.push_back(std::move(texture));
    texture_cache_[key] = index;
    return index;
}

float extension_number(const tinygltf::ExtensionMap& extensions, const char* extension,
                       const char* key, float fallback) {
    auto it = extensions.find(extension);
    if (it == extensions.end() || !it->second.IsObject() || !it->second.Has(key)) return fallback;
    const tinygltf::Value& value = it->second.Get(key);
    return value.IsNumber() ? float(value.GetNumberAsDouble()) : fallback;
}

Vec3f vec3_or(const std::vector<double>& v, Vec3f fallback) {
    return v.size() >= 3 ? Vec3f(float(v[0]), float(v[1]), float(v[2])) : fallback;
}

// An extension's array of 3 numbers, `fallback` when absent or malformed.
Vec3f extension_vec3(const tinygltf::ExtensionMap& extensions, const char* extension, const char* key,
                     Vec3f fallback) {
    auto it = extensions.find(extension);
    if (it == extensions.end() || !it->second.IsObject() || !it->second.Has(key)) return fallback;
    const tinygltf::Value& value = it->second.Get(key);
    if (!value.IsArray() || value.ArrayLen() != 3) return fallback;
    Vec3f v;
    for (int i = 0; i < 3; ++i) {
        if (!value.Get(i).IsNumber()) return fallback;
        v[i] = float(value.Get(i).GetNumberAsDouble());
    }
    return v;
}

// Whether an extension object names a texture under `key`.
bool extension_has(const tinygltf::ExtensionMap& extensions, const char* extension, const char* key) {
    auto it = extensions.find(extension);
    return it != extensions.end() && it->second.IsObject() && it->second.Has(key);
}

// KHR_materials_specular: the factors only; its textures would need a
// per-texel layer the material model does not carry, so they are dropped
// (warned once per file).
void GltfReader::convert_specular(const tinygltf::ExtensionMap& extensions, Material& m) {
    const char* ext = "KHR_materials_specular";
    m.specular = extension_number(extensions, ext, "specularFactor", 1.0f);
    m.specular_color = extension_vec3(extensions, ext, "specularColorFactor", Vec3f(1.0f));
    const bool textured = extension_has(extensions, ext, "specularTexture") ||
                          extension_has(extensions, ext, "specularColorTexture");
    if (textured && !warned_specular_textures_) warn(path_, "ignoring KHR_materials_specular textures (factors used)");
    warned_specular_textures_ = warned_specular_textures_ || textured;
}

void GltfReader::convert_materials(Scene& scene) {
    for (size_t i = 0; i < model_.materials.size(); ++i) {
        const tinygltf::Material& gltf = model_.materials[i];
        const auto& pbr = gltf.pbrMetallicRoughness;
        Material m;
        m.name = gltf.name.empty() ? "material" + std::to_string(i) : gltf.name;
        m.base_color = vec3_or(pbr.baseColorFactor, Vec3f(1.0f));
        m.alpha = pbr.baseColorFactor.size() >= 4 ? float(pbr.baseColorFactor[3]) : 1.0f;
        m.base_color_texture = texture_index(pbr.baseColorTexture.index, TextureEncoding::Srgb8, scene);
        m.metallic = float(pbr.metallicFactor);
        m.roughness = float(pbr.roughnessFactor);
        m.metallic_roughness_texture =
            texture_index(pbr.metallicRoughnessTexture.index, TextureEncoding::Linear8, scene);
        m.normal_texture = texture_index(gltf.normalTexture.index, TextureEncoding::Linear8, scene);
        m.normal_scale = float(gltf.normalTexture.scale);
        m.emission = vec3_or(gltf.emissiveFactor, Vec3f(0.0f));
        m.emission_texture = texture_index(gltf.emissiveTexture.index, TextureEncoding::Srgb8, scene);
        // A texture multiplies the factor, so a texture with a zero factor emits nothing.
        m.emission_strength = extension_number(gltf.extensions, "KHR_materials_emissive_strength",
                                               "emissiveStrength", 1.0f);
        m.transmission = extension_number(gltf.extensions, "KHR_materials_transmission",
                                          "transmissionFactor", 0.0f);
        m.ior = extension_number(gltf.extensions, "KHR_materials_ior", "ior", 1.5f);
        convert_specular(gltf.extensions, m);
        if (gltf.alphaMode == "MASK") m.alpha_mode = AlphaMode::Mask;
        else if (gltf.alphaMode == "BLEND") m.alpha_mode = AlphaMode::Blend;
        else m.alpha_mode = AlphaMode::Opaque;
        m.alpha_cutoff = float(gltf.alphaCutoff);
        m.two_sided_emission = gltf.doubleSided;
        scene.materials.push_back(std::move(m));
    }
}

uint32_t GltfReader::material_index(int gltf_material, Scene& scene) {
    if (gltf_material >= 0) {
        if (size_t(gltf_material) >= model_.materials.size())
            fail("material " + std::to_string(gltf_material) + " does not exist");
        return uint32_t(gltf_material);  // materials are converted in glTF order
    }
    if (default_material_ < 0) {
        // glTF's default material: white, fully rough dielectric.
        Material m;
        m.name = "gltf-default";
        m.base_color = Vec3f(1.0f);
        m.two_sided_emission = false;
        default_material_ = int(scene.materials.size());
        scene.materials.push_back(m);
    }
    return uint32_t(default_material_);
}

// --- Meshes -----------------------------------------------------------------

bool GltfReader::convert_primitive(const tinygltf::Primitive& primitive, const std::string& name,
                                   Scene& scene, Mesh& mesh) {
    const int mode = primitive.mode < 0 ? TINYGLTF_MODE_TRIANGLES : primitive.mode;
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        if (!warned_non_triangles_) warn(path_, "skipping point and line primitives (" + name + ")");
        warned_non_triangles_ = true;
        return false;
    }
    auto position_it = primitive.attributes.find("POSITION");
    if (position_it == primitive.attributes.end()) fail(name + ": primitive has no POSITION");

    mesh.name = name;
    int components = 0;
    std::vector<float> positions =
        read_floats(position_it->second, "POSITION", {TINYGLTF_TYPE_VEC3}, components);
    const size_t vertex_count = positions.size() / 3;
    budgeted_resize(mesh.positions, vertex_count, path_ + ": " + name + ": vertex array");
    for (size_t i = 0; i < vertex_count; ++i) {
        Vec3f p(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
        if (!is_finite(p))
            fail(name + ": POSITION " + std::to_string(i) + " is not finite (NaN or infinity)");
        mesh.positions[i] = p;
    }

    if (auto it = primitive.attributes.find("NORMAL"); it != primitive.attributes.end()) {
        std::vector<float> normals = read_floats(it->second, "NORMAL", {TINYGLTF_TYPE_VEC3}, components);
        if (normals.size() != positions.size()) fail(name + ": NORMAL count differs from POSITION count");
        budgeted_resize(mesh.normals, vertex_count, path_ + ": " + name + ": normal array");
        for (size_t i = 0; i < vertex_count; ++i) {
            Vec3f n(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]);
            if (!is_finite(n)) fail(name + ": NORMAL " + std::to_string(i) + " is not finite");
            mesh.normals[i] = n;
        }
    }
    if (auto it = primitive.attributes.find("TEXCOORD_0"); it != primitive.attributes.end()) {
        std::vector<float> uvs = read_floats(it->second, "TEXCOORD_0", {TINYGLTF_TYPE_VEC2}, components);
        if (uvs.size() != vertex_count * 2) fail(name + ": TEXCOORD_0 count differs from POSITION count");
        budgeted_resize(mesh.uvs, vertex_count, path_ + ": " + name + ": texture coordinate array");
        for (size_t i = 0; i < vertex_count; ++i) {
            if (!std::isfinite(uvs[2 * i]) || !std::isfinite(uvs[2 * i + 1]))
                fail(name + ": TEXCOORD_0 " + std::to_string(i) + " is not finite");
            mesh.uvs[i] = Vec2f{uvs[2 * i], uvs[2 * i + 1]};
        }
    }
    if (auto it = primitive.attributes.find("TANGENT"); it != primitive.attributes.end()) {
        std::vector<float> tangents = read_floats(it->second, "TANGENT", {TINYGLTF_TYPE_VEC4}, components);
        if (tangents.size() != vertex_count * 4) fail(name + ": TANGENT count differs from POSITION count");
        budgeted_resize(mesh.tangents, vertex_count, path_ + ": " + name + ": tangent array");
        for (size_t i = 0; i < vertex_count; ++i) {
            const float* t = &tangents[4 * i];
            if (!std::isfinite(t[0]) || !std::isfinite(t[1]) || !std::isfinite(t[2]) || !std::isfinite(t[3]))
                fail(name + ": TANGENT " + std::to_string(i) + " is not finite");
            mesh.tangents[i] = Vec4f{t[0], t[1], t[2], t[3]};
        }
    }

    // Vertex order: the index list, or 0..n-1 for non-indexed primitives.
    std::vector<uint32_t> order;
    if (primitive.indices >= 0) {
        order = read_indices(primitive.indices);
        for (size_t i = 0; i < order.size(); ++i)
            if (order[i] >= vertex_count)
                fail(name + ": index " + std::to_string(i) + " = " + std::to_string(order[i]) +
                     " is out of range (" + std::to_string(vertex_count) + " vertices)");
    } else {
        budgeted_resize(order, vertex_count, path_ + ": " + name + ": index array");
        for (size_t i = 0; i < vertex_count; ++i) order[i] = uint32_t(i);
    }

    if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (order.size() % 3 != 0) fail(name + ": triangle list length " + std::to_string(order.size()) +
                                        " is not a multiple of 3");
        mesh.indices = std::move(order);
    } else if (order.size() >= 3) {
        budgeted_reserve(mesh.indices, (order.size() - 2) * 3, path_ + ": " + name + ": index array");
        for (size_t i = 2; i < order.size(); ++i) {
            if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
                // Every other triangle of a strip is flipped to keep the winding.
                if (i % 2 == 0) mesh.indices.insert(mesh.indices.end(), {order[i - 2], order[i - 1], order[i]});
                else mesh.indices.insert(mesh.indices.end(), {order[i - 1], order[i - 2], order[i]});
            } else {
                mesh.indices.insert(mesh.indices.end(), {order[0], order[i - 1], order[i]});
            }
        }
    }
    if (mesh.indices.empty()) return false;

    checked_index_count(path_ + ": " + name + ": triangle count", mesh.indices.size() / 3);
    const uint32_t material = material_index(primitive.material, scene);
    budgeted_resize(mesh.material_ids, mesh.triangle_count(), path_ + ": " + name + ": material id array");
    std::fill(mesh.material_ids.begin(), mesh.material_ids.end(), material);
    if (mesh.normals.empty() && options_.compute_missing_normals) mesh.compute_vertex_normals();
    return true;
}

const std::vector<uint32_t>& GltfReader::mesh_primitives(int mesh_index, Scene& scene) {
    if (auto it = mesh_cache_.find(mesh_index); it != mesh_cache_.end()) return it->second;
    if (mesh_index < 0 || size_t(mesh_index) >= model_.meshes.size())
        fail("mesh " + std::to_string(mesh_index) + " does not exist");
    const tinygltf::Mesh& gltf = model_.meshes[size_t(mesh_index)];
    std::vector<uint32_t> ids;
    for (size_t p = 0; p < gltf.primitives.size(); ++p) {
        std::string name = (gltf.name.empty() ? "mesh" + std::to_string(mesh_index) : gltf.name);
        if (gltf.primitives.size() > 1) name += "#" + std::to_string(p);
        Mesh mesh;
        if (!convert_primitive(gltf.primitives[p], name, scene, mesh)) continue;
        ids.push_back(uint32_t(scene.meshes.size()));
        scene.meshes.push_back(std::move(mesh));
    }
    return mesh_cache_[mesh_index] = std::move(ids);
}

// --- Nodes, cameras, lights -------------------------------------------------

// Rotation matrix of a unit quaternion (x, y, z, w).
Affine3f quaternion_rotation(double x, double y, double z, double w) {
    double n = std::sqrt(x * x + y * y + z * z + w * w);
    if (n > 0) { x /= n; y /= n; z /= n; w /= n; }
    Affine3f r;
    r.m[0][0] = float(1 - 2 * (y * y + z * z));
    r.m[0][1] = float(2 * (x * y - z * w));
    r.m[0][2] = float(2 * (x * z + y * w));
    r.m[1][0] = float(2 * (x * y + z * w));
    r.m[1][1] = float(1 - 2 * (x * x + z * z));
    r.m[1][2] = float(2 * (y * z - x * w));
    r.m[2][0] = float(2 * (x * z - y * w));
    r.m[2][1] = float(2 * (y * z + x * w));
    r.m[2][2] = float(1 - 2 * (x * x + y * y));
    return r;
}

Affine3f GltfReader::local_transform(const tinygltf::Node& node, int node_index) const {
    auto finite = [](const std::vector<double>& v) {
        return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
    };
    const std::string where = "node " + std::to_string(node_index);
    if (!node.matrix.empty()) {
        if (node.matrix.size() != 16 || !finite(node.matrix)) fail(where + ": invalid matrix");
        return Affine3f::from_column_major(node.matrix.data());
    }
    Affine3f t, r, s;
    if (!node.translation.empty()) {
        if (node.translation.size() != 3 || !finite(node.translation)) fail(where + ": invalid translation");
        t = Affine3f::translation(vec3_or(node.translation, Vec3f(0.0f)));
    }
    if (!node.rotation.empty()) {
        if (node.rotation.size() != 4 || !finite(node.rotation)) fail(where + ": invalid rotation");
        r = quaternion_rotation(node.rotation[0], node.rotation[1], node.rotation[2], node.rotation[3]);
    }
    if (!node.scale.empty()) {
        if (node.scale.size() != 3 || !finite(node.scale)) fail(where + ": invalid scale");
        s = Affine3f::scale(vec3_or(node.scale, Vec3f(1.0f)));
    }
    return t * r * s;
}

void GltfReader::add_light(int light_index, const Affine3f& world, Scene& scene) const {
    if (light_index < 0 || size_t(light_index) >= model_.lights.size())
        fail("KHR_lights_punctual light " + std::to_string(light_index) + " does not exist");
    const tinygltf::Light& gltf = model_.lights[size_t(light_index)];
    Light light;
    if (gltf.type == "point") light.type = LightType::Point;
    else if (gltf.type == "spot") light.type = LightType::Spot;
    else if (gltf.type == "directional") light.type = LightType::Directional;
    else fail("light " + std::to_string(light_index) + ": unknown type '" + gltf.type + "'");
    light.position = world.transform_point(Vec3f(0.0f));
    Vec3f direction = world.transform_vector(Vec3f(0, 0, -1));  // lights shine down their -Z
    if (length(direction) > 0) light.direction = normalize(direction);
    light.color = vec3_or(gltf.color, Vec3f(1.0f));
    light.intensity = float(gltf.intensity);
    light.inner_cone_radians = float(gltf.spot.innerConeAngle);
    light.outer_cone_radians = float(gltf.spot.outerConeAngle);
    scene.lights.push_back(light);
}

void GltfReader::set_camera(int camera_index, const Affine3f& world, Scene& scene) {
    if (camera_index < 0 || size_t(camera_index) >= model_.cameras.size())
        fail("camera " + std::to_string(camera_index) + " does not exist");
    const tinygltf::Camera& gltf = model_.cameras[size_t(camera_index)];
    if (gltf.type != "perspective") {
        warn(path_, "ignoring " + gltf.type + " camera " + std::to_string(camera_index));
        return;
    }
    Vec3f forward = world.transform_vector(Vec3f(0, 0, -1));
    Vec3f up = world.transform_vector(Vec3f(0, 1, 0));
    if (!(length(forward) > 0) || !(length(up) > 0)) fail("camera node has a degenerate transform");
    Camera camera;
    camera.eye = world.transform_point(Vec3f(0.0f));
    camera.target = camera.eye + normalize(forward);
    camera.up = normalize(up);
    camera.vfov_degrees = float(gltf.perspective.yfov) * 180.0f / kPi;
    if (!(camera.vfov_degrees > 0.0f && camera.vfov_degrees < 180.0f))
        fail("camera " + std::to_string(camera_index) + ": yfov out of range");
    scene.camera = camera;
}

// Node hierarchies are DAGs in practice: a node listed as the child of several
// parents is visited once per path. Both limits stop malicious files: a deep
// chain (recursion depth) and a few shared levels that multiply into
// billions of paths (2 children per level, 40 levels).
constexpr int kMaxNodeDepth = 1000;
constexpr size_t kMaxNodeVisits = size_t(1) << 22;

// The instances of a node's mesh: a skinned one at the identity (skinning
// yields world space), the others at `world`, and linked to the node when an
// ancestor (or the node) is animated.
void GltfReader::add_instances(int node_index, const Affine3f& world, bool animated, Scene& scene) {
    const tinygltf::Node& node = model_.nodes[size_t(node_index)];
    const bool skinned = node.skin >= 0;
    const bool deformed = skinned || morph_target_count(node.mesh) > 0;
    const std::vector<uint32_t>& meshes = deformed ? deformed_meshes(node_index, scene) : mesh_primitives(node.mesh, scene);
    for (uint32_t mesh : meshes) {
        const auto instance = uint32_t(scene.instances.size());
        budgeted_push_back(scene.instances, Instance{mesh, skinned ? Affine3f::identity() : world},
                           path_ + ": instance array");
        if (animated && !skinned)
            scene.animation.instances.push_back(InstanceAnimation{instance, uint32_t(animated_node(node_index, scene))});
    }
}

void GltfReader::visit_node(int node_index, const Affine3f& parent, Scene& scene, int depth, bool animated) {
    if (node_index < 0 || size_t(node_index) >= model_.nodes.size())
        fail("node " + std::to_string(node_index) + " does not exist");
    if (on_path_[size_t(node_index)])
        fail("node " + std::to_string(node_index) + " is its own ancestor (cycle in the node tree)");
    if (depth > kMaxNodeDepth)
        fail("node " + std::to_string(node_index) + " is nested more than " + std::to_string(kMaxNodeDepth) +
             " levels deep");
    if (++node_visits_ > kMaxNodeVisits)
        fail("the node hierarchy expands to more than " + std::to_string(kMaxNodeVisits) +
             " node instances (nodes shared by many parents)");
    const tinygltf::Node& node = model_.nodes[size_t(node_index)];
    const Affine3f world = parent * local_transform(node, node_index);
    animated = animated || node_tracks_.count(node_index) != 0;

    if (node.mesh >= 0) add_instances(node_index, world, animated, scene);
    if (node.camera >= 0 && !scene.camera) set_camera(node.camera, world, scene);
    if (auto it = node.extensions.find("KHR_lights_punctual"); it != node.extensions.end()) {
        if (it->second.Has("light") && it->second.Get("light").IsNumber()) {
            // Range-checked before the cast: converting 1e300 to int is undefined.
            const double light = it->second.Get("light").GetNumberAsDouble();
            add_light(light >= 0.0 && light < double(std::numeric_limits<int>::max()) ? int(light) : -1, world,
                      scene);
        }
    }

    on_path_[size_t(node_index)] = 1;
    for (int child : node.children) visit_node(child, world, scene, depth + 1, animated);
    on_path_[size_t(node_index)] = 0;
}

// --- Animation --------------------------------------------------------------

// A quaternion scaled to unit length; false for a zero one.
bool normalize_quaternion(float* q) {
    const double n = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
    if (!(n > 0.0)) return false;
    for (int i = 0; i < 4; ++i) q[i] = float(q[i] / n);
    return true;
}

// A sampler's keys. Times must be float scalars, finite and strictly
// increasing; outputs hold `width` floats per key (three groups per key for
// CUBICSPLINE), float or, for rotations and weights, normalised integers.
Track GltfReader::read_track(const tinygltf::Animation& animation, int sampler_index, TrackKind kind, int width,
                             const std::string& where) const {
    if (sampler_index < 0 || size_t(sampler_index) >= animation.samplers.size())
        fail(where + ": sampler " + std::to_string(sampler_index) + " does not exist");
    const tinygltf::AnimationSampler& sampler = animation.samplers[size_t(sampler_index)];
    const std::string at = where + " (sampler " + std::to_string(sampler_index) + ")";
    Track track;
    track.width = width;
    if (sampler.interpolation == "LINEAR") track.interpolation = Interpolation::Linear;
    else if (sampler.interpolation == "STEP") track.interpolation = Interpolation::Step;
    else if (sampler.interpolation == "CUBICSPLINE") track.interpolation = Interpolation::CubicSpline;
    else fail(at + ": unknown interpolation '" + sampler.interpolation + "'");

    const ElementView input = element_view(sampler.input, "animation input");
    if (model_.accessors[size_t(sampler.input)].type != TINYGLTF_TYPE_SCALAR ||
        input.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT)
        fail(at + ": input accessor " + std::to_string(sampler.input) + " must hold float scalars");
    int components = 0;
    track.times = read_floats(sampler.input, "animation input", {TINYGLTF_TYPE_SCALAR}, components);
    if (track.times.empty()) fail(at + ": input accessor " + std::to_string(sampler.input) + " has no keys");
    for (size_t k = 0; k < track.times.size(); ++k) {
        if (!std::isfinite(track.times[k])) fail(at + ": key time " + std::to_string(k) + " is not finite");
        if (k > 0 && !(track.times[k] > track.times[k - 1]))
            fail(at + ": key times are not strictly increasing (key " + std::to_string(k) + ")");
    }

    const ElementView output = element_view(sampler.output, "animation output");
    const bool quantized_ok = kind == TrackKind::Rotation || kind == TrackKind::Weights;
    const bool quantized = output.normalized && component_size(output.component_type) <= 2;
    if (output.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT && !(quantized_ok && quantized))
        fail(at + ": output accessor " + std::to_string(sampler.output) + " has an unsupported component type");
    const int type = kind == TrackKind::Rotation ? TINYGLTF_TYPE_VEC4
                     : kind == TrackKind::Weights ? TINYGLTF_TYPE_SCALAR : TINYGLTF_TYPE_VEC3;
    track.values = read_floats(sampler.output, "animation output", {type}, components);
    const size_t groups = track.interpolation == Interpolation::CubicSpline ? 3 : 1;
    const size_t expected = track.times.size() * groups * size_t(width);
    if (track.values.size() != expected)
        fail(at + ": output accessor " + std::to_string(sampler.output) + " holds " +
             std::to_string(track.values.size()) + " floats, expected " + std::to_string(expected) + " (" +
             std::to_string(track.times.size()) + " keys)");
    for (float v : track.values)
        if (!std::isfinite(v)) fail(at + ": output accessor " + std::to_string(sampler.output) + " is not finite");
    if (kind == TrackKind::Rotation) {
        // Key values are unit quaternions; cubic tangents (groups 0 and 2) are not.
        const size_t value_group = groups == 3 ? 1 : 0;
        for (size_t k = 0; k < track.times.size(); ++k)
            if (!normalize_quaternion(&track.values[(k * groups + value_group) * 4]))
                fail(at + ": rotation key " + std::to_string(k) + " is a zero quaternion");
    }
    return track;
}

size_t GltfReader::morph_target_count(int mesh_index) const {
    if (mesh_index < 0 || size_t(mesh_index) >= model_.meshes.size())
        fail("mesh " + std::to_string(mesh_index) + " does not exist");
    size_t count = 0;
    for (const auto& primitive : model_.meshes[size_t(mesh_index)].primitives)
        count = std::max(count, primitive.targets.size());
    return count;
}

// The clip LoadOptions::animation names (a name first, then an index), or the first.
size_t GltfReader::chosen_animation() const {
    const std::string& wanted = options_.animation;
    if (wanted.empty()) return 0;
    for (size_t i = 0; i < model_.animations.size(); ++i)
        if (model_.animations[i].name == wanted) return i;
    if (wanted.find_first_not_of("0123456789") == std::string::npos && wanted.size() < 10) {
        const size_t index = std::stoul(wanted);
        if (index < model_.animations.size()) return index;
    }
    std::string names;
    for (size_t i = 0; i < model_.animations.size(); ++i)
        names += (i ? ", " : "") + std::to_string(i) + " '" + model_.animations[i].name + "'";
    fail("no animation '" + wanted + "' (the file has " +
         (model_.animations.empty() ? std::string("none") : names) + ")");
}

void GltfReader::read_animation() {
    if (model_.animations.empty()) {
        (void)chosen_animation();  // a clip asked of a still file is an error too
        return;
    }
    const size_t chosen = chosen_animation();
    const tinygltf::Animation& animation = model_.animations[chosen];
    for (const tinygltf::Animation& a : model_.animations) clips_.push_back(a.name);
    std::set<std::pair<int, std::string>> seen;
    for (size_t c = 0; c < animation.channels.size(); ++c) {
        const tinygltf::AnimationChannel& channel = animation.channels[c];
        const std::string where = "animation " + std::to_string(chosen) + " channel " + std::to_string(c);
        if (channel.target_node < 0) continue;  // targets given by extensions only
        if (size_t(channel.target_node) >= model_.nodes.size())
            fail(where + ": node " + std::to_string(channel.target_node) + " does not exist");
        const int index = channel.target_node;
        const tinygltf::Node& node = model_.nodes[size_t(index)];
        const std::string& path = channel.target_path;
        const std::string target = "node " + std::to_string(index) + " " + path;
        if (path != "translation" && path != "rotation" && path != "scale" && path != "weights") {
            if (!warned_channel_path_) warn(path_, where + ": ignoring target path '" + path + "'");
            warned_channel_path_ = true;
            continue;
        }
        if (!seen.insert({index, path}).second) fail(where + ": " + target + " is animated twice");
        Track track;
        if (path == "weights") {
            const size_t targets = node.mesh >= 0 ? morph_target_count(node.mesh) : 0;
            if (targets == 0) fail(where + ": node " + std::to_string(index) + " has no morph targets to weight");
            track = read_track(animation, channel.sampler, TrackKind::Weights, int(targets), where);
            weight_tracks_[index] = track;
        } else {
            if (!node.matrix.empty()) fail(where + ": node " + std::to_string(index) + " has a matrix, so it cannot be animated");
            NodeTracks& tracks = node_tracks_[index];
            if (path == "translation") track = tracks.translation = read_track(animation, channel.sampler, TrackKind::Translation, 3, where);
            else if (path == "rotation") track = tracks.rotation = read_track(animation, channel.sampler, TrackKind::Rotation, 4, where);
            else track = tracks.scale = read_track(animation, channel.sampler, TrackKind::Scale, 3, where);
        }
        account_animation(track.times.size() + track.values.size(), sizeof(float));
        key_start_ = has_keys_ ? std::min(key_start_, track.times.front()) : track.times.front();
        key_end_ = has_keys_ ? std::max(key_end_, track.times.back()) : track.times.back();
        has_keys_ = true;
    }
}

// The Animation::nodes entry of a glTF node, created on first use after its
// ancestors (so a parent's index is always smaller than its child's).
int32_t GltfReader::animated_node(int node_index, Scene& scene, int depth) {
    if (node_index < 0 || size_t(node_index) >= model_.nodes.size())
        fail("node " + std::to_string(node_index) + " does not exist");
    if (animation_node_[size_t(node_index)] >= 0) return animation_node_[size_t(node_index)];
    if (depth > kMaxNodeDepth)
        fail("node " + std::to_string(node_index) + ": its ancestors form a cycle or a chain deeper than " +
             std::to_string(kMaxNodeDepth) + " levels");
    const int gltf_parent = node_parent_[size_t(node_index)];
    const int32_t parent = gltf_parent >= 0 ? animated_node(gltf_parent, scene, depth + 1) : -1;
    const tinygltf::Node& gltf = model_.nodes[size_t(node_index)];
    (void)local_transform(gltf, node_index);  // validates the rest values
    AnimatedNode node;
    node.name = gltf.name.empty() ? "node" + std::to_string(node_index) : gltf.name;
    node.parent = parent;
    if (!gltf.matrix.empty()) {
        node.matrix = Affine3f::from_column_major(gltf.matrix.data());
    } else {
        node.translation = vec3_or(gltf.translation, Vec3f(0.0f));
        node.scale = vec3_or(gltf.scale, Vec3f(1.0f));
        if (gltf.rotation.size() == 4) {
            float q[4] = {float(gltf.rotation[0]), float(gltf.rotation[1]), float(gltf.rotation[2]),
                          float(gltf.rotation[3])};
            if (normalize_quaternion(q)) node.rotation = Vec4f{q[0], q[1], q[2], q[3]};
        }
    }
    if (auto it = node_tracks_.find(node_index); it != node_tracks_.end()) {
        node.translation_track = it->second.translation;
        node.rotation_track = it->second.rotation;
        node.scale_track = it->second.scale;
    }
    const auto index = int32_t(scene.animation.nodes.size());
    budgeted_push_back(scene.animation.nodes, std::move(node), path_ + ": animation node array");
    animation_node_[size_t(node_index)] = index;
    return index;
}

// The rf meshes of a skinned or morphed node: its mesh converted anew for
// this node, since the skin and the morph weights belong to the node.
const std::vector<uint32_t>& GltfReader::deformed_meshes(int node_index, Scene& scene) {
    const tinygltf::Node& node = model_.nodes[size_t(node_index)];
    const auto key = std::make_pair(node.mesh, node_index);
    if (auto it = deformed_cache_.find(key); it != deformed_cache_.end()) return it->second;
    (void)morph_target_count(node.mesh);  // checks the mesh index
    const tinygltf::Mesh& gltf = model_.meshes[size_t(node.mesh)];
    std::vector<uint32_t> ids;
    for (size_t p = 0; p < gltf.primitives.size(); ++p) {
        std::string name = (gltf.name.empty() ? "mesh" + std::to_string(node.mesh) : gltf.name);
        if (gltf.primitives.size() > 1) name += "#" + std::to_string(p);
        Mesh mesh;
        if (!convert_primitive(gltf.primitives[p], name, scene, mesh)) continue;
        const auto id = uint32_t(scene.meshes.size());
        const size_t vertex_count = mesh.positions.size();
        account_animation(mesh.memory_bytes(), 2);  // the copy and its rest positions (Animation::rest_*)
        scene.meshes.push_back(std::move(mesh));
        if (morph_target_count(node.mesh) > 0)
            add_morph_targets(gltf.primitives[p], node_index, name, id, vertex_count, scene);
        if (node.skin >= 0) add_skin(node.skin, gltf.primitives[p], name, id, vertex_count, scene);
        ids.push_back(id);
    }
    return deformed_cache_[key] = std::move(ids);
}

// Each accessor is read once: a morphed mesh is converted again for every
// node using it, and reading the same deltas again per node was slow.
std::vector<Vec3f> GltfReader::read_deltas(int accessor_index, const std::string& what, size_t vertex_count) {
    if (auto it = delta_cache_.find({accessor_index, vertex_count}); it != delta_cache_.end()) return it->second;
    std::vector<Vec3f> out;
    budgeted_resize(out, vertex_count, path_ + ": " + what);
    if (accessor_index < 0) return out;  // a target without this attribute moves nothing
    int components = 0;
    const std::vector<float> values = read_floats(accessor_index, what.c_str(), {TINYGLTF_TYPE_VEC3}, components);
    if (values.size() != vertex_count * 3) fail(what + ": count differs from POSITION count");
    for (size_t i = 0; i < vertex_count; ++i) {
        out[i] = Vec3f(values[3 * i], values[3 * i + 1], values[3 * i + 2]);
        if (!is_finite(out[i])) fail(what + ": delta " + std::to_string(i) + " is not finite");
    }
    return delta_cache_[{accessor_index, vertex_count}] = out;
}

void GltfReader::add_morph_targets(const tinygltf::Primitive& primitive, int node_index, const std::string& name,
                                   uint32_t mesh_id, size_t vertex_count, Scene& scene) {
    const tinygltf::Node& node = model_.nodes[size_t(node_index)];
    const tinygltf::Mesh& gltf = model_.meshes[size_t(node.mesh)];
    const size_t targets = morph_target_count(node.mesh);
    if (primitive.targets.size() != targets)
        fail(name + ": has " + std::to_string(primitive.targets.size()) + " morph targets, another primitive " +
             std::to_string(targets));
    auto attribute = [](const std::map<std::string, int>& target, const char* key) {
        auto it = target.find(key);
        return it == target.end() ? -1 : it->second;
    };
    bool normals = false;
    for (const auto& target : primitive.targets) normals = normals || attribute(target, "NORMAL") >= 0;
    account_animation(targets * (normals ? 2 : 1) * vertex_count, sizeof(Vec3f));
    MorphTargets morph;
    morph.mesh = mesh_id;
    for (size_t t = 0; t < targets; ++t) {
        const std::string what = name + ": morph target " + std::to_string(t);
        morph.position_deltas.push_back(
            read_deltas(attribute(primitive.targets[t], "POSITION"), what + " POSITION", vertex_count));
        if (normals)
            morph.normal_deltas.push_back(
                read_deltas(attribute(primitive.targets[t], "NORMAL"), what + " NORMAL", vertex_count));
    }
    // The node's weights override the mesh's; both default to zero.
    const std::vector<double>& defaults = !node.weights.empty() ? node.weights : gltf.weights;
    if (!defaults.empty() && defaults.size() != targets)
        fail(name + ": " + std::to_string(defaults.size()) + " default weights for " + std::to_string(targets) +
             " morph targets");
    morph.default_weights.assign(targets, 0.0f);
    for (size_t t = 0; t < defaults.size(); ++t) {
        if (!std::isfinite(defaults[t])) fail(name + ": default morph weight " + std::to_string(t) + " is not finite");
        morph.default_weights[t] = float(defaults[t]);
    }
    if (auto it = weight_tracks_.find(node_index); it != weight_tracks_.end()) morph.weights = it->second;
    scene.animation.morphs.push_back(std::move(morph));
}

// JOINTS_n (unsigned byte/short) or WEIGHTS_n (float, normalised unsigned
// byte/short): four values per vertex.
std::vector<float> GltfReader::read_skin_attribute(int accessor_index, const std::string& what, size_t vertex_count,
                                                   bool joints) const {
    const ElementView view = element_view(accessor_index, what.c_str());
    const int type = view.component_type;
    const bool small_unsigned =
        type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE || type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
    const bool ok = joints ? small_unsigned && !view.normalized
                           : type == TINYGLTF_COMPONENT_TYPE_FLOAT || (small_unsigned && view.normalized);
    if (!ok)
        fail(what + ": must be " +
             (joints ? "unsigned byte or short" : "float or normalized unsigned byte or short") + " VEC4");
    int components = 0;
    std::vector<float> values = read_floats(accessor_index, what.c_str(), {TINYGLTF_TYPE_VEC4}, components);
    if (values.size() != vertex_count * 4) fail(what + ": count differs from POSITION count");
    return values;
}

// Up to two influence sets (8 per vertex); zero weights are dropped, and of
// more than 4 the largest (ties in file order); the rest renormalised to sum to 1.
void GltfReader::read_influences(const tinygltf::Primitive& primitive, const std::string& name, size_t vertex_count,
                                 Skin& skin) const {
    std::vector<std::vector<float>> joints, weights;
    for (int set = 0; set < 2; ++set) {
        const std::string j = "JOINTS_" + std::to_string(set), w = "WEIGHTS_" + std::to_string(set);
        auto jt = primitive.attributes.find(j), wt = primitive.attributes.find(w);
        if (jt == primitive.attributes.end() && wt == primitive.attributes.end()) break;
        if (jt == primitive.attributes.end() || wt == primitive.attributes.end())
            fail(name + ": " + j + " and " + w + " must come together");
        joints.push_back(read_skin_attribute(jt->second, name + ": " + j, vertex_count, true));
        weights.push_back(read_skin_attribute(wt->second, name + ": " + w, vertex_count, false));
    }
    if (joints.empty()) fail(name + ": skinned mesh has no JOINTS_0/WEIGHTS_0");
    budgeted_resize(skin.vertex_joints, vertex_count, path_ + ": " + name + ": skin joint array");
    budgeted_resize(skin.vertex_weights, vertex_count, path_ + ": " + name + ": skin weight array");
    const size_t joint_count = skin.joints.size();
    for (size_t v = 0; v < vertex_count; ++v) {
        std::pair<float, uint32_t> influences[8];
        size_t n = 0;
        for (size_t set = 0; set < joints.size(); ++set)
            for (size_t k = 0; k < 4; ++k) {
                const float weight = weights[set][4 * v + k];
                const auto joint = uint32_t(joints[set][4 * v + k]);
                if (!(weight >= 0.0f) || !std::isfinite(weight))
                    fail(name + ": vertex " + std::to_string(v) + ": skin weight is negative or not finite");
                if (weight == 0.0f) continue;
                if (joint >= joint_count)
                    fail(name + ": vertex " + std::to_string(v) + ": joint " + std::to_string(joint) +
                         " is out of range (" + std::to_string(joint_count) + " joints)");
                influences[n++] = {weight, joint};
            }
        if (n > 4) {
            std::stable_sort(influences, influences + n, [](const auto& a, const auto& b) { return a.first > b.first; });
            n = 4;
        }
        float sum = 0.0f;
        for (size_t k = 0; k < n; ++k) sum += influences[k].first;
        if (!(sum > 0.0f)) fail(name + ": vertex " + std::to_string(v) + " has no skin weight");
        float w[4] = {0, 0, 0, 0};
        for (size_t k = 0; k < n; ++k) {
            skin.vertex_joints[v][k] = uint16_t(influences[k].second);
            w[k] = influences[k].first / sum;
        }
        for (size_t k = n; k < 4; ++k) skin.vertex_joints[v][k] = 0;
        skin.vertex_weights[v] = Vec4f{w[0], w[1], w[2], w[3]};
    }
}

void GltfReader::add_skin(int skin_index, const tinygltf::Primitive& primitive, const std::string& name,
                          uint32_t mesh_id, size_t vertex_count, Scene& scene) {
    if (skin_index < 0 || size_t(skin_index) >= model_.skins.size())
        fail("skin " + std::to_string(skin_index) + " does not exist");
    const tinygltf::Skin& gltf = model_.skins[size_t(skin_index)];
    const std::string where = "skin " + std::to_string(skin_index);
    if (gltf.joints.empty()) fail(where + ": has no joints");
    if (gltf.joints.size() > 65536) fail(where + ": has more than 65536 joints");
    // Per copy: joints and inverse binds, and as many joint matrices in each Scene::set_time.
    account_animation(gltf.joints.size(), sizeof(uint32_t) + 2 * sizeof(Affine3f));
    account_animation(vertex_count, sizeof(std::array<uint16_t, 4>) + sizeof(Vec4f));
    Skin skin;
    skin.mesh = mesh_id;
    for (int joint : gltf.joints) {
        if (joint < 0 || size_t(joint) >= model_.nodes.size())
            fail(where + ": joint node " + std::to_string(joint) + " does not exist");
        skin.joints.push_back(uint32_t(animated_node(joint, scene)));
    }
    skin.inverse_bind.assign(gltf.joints.size(), Affine3f::identity());
    if (gltf.inverseBindMatrices >= 0) {
        const std::string what = where + ": inverseBindMatrices";
        const ElementView view = element_view(gltf.inverseBindMatrices, what.c_str());
        if (view.component_type != TINYGLTF_COMPONENT_TYPE_FLOAT) fail(what + ": must be float MAT4");
        int components = 0;
        const std::vector<float> m = read_floats(gltf.inverseBindMatrices, what.c_str(), {TINYGLTF_TYPE_MAT4}, components);
        if (m.size() / 16 < gltf.joints.size())
            fail(what + ": " + std::to_string(m.size() / 16) + " matrices for " + std::to_string(gltf.joints.size()) +
                 " joints");
        for (size_t j = 0; j < gltf.joints.size(); ++j) {
            double column_major[16];
            for (int k = 0; k < 16; ++k) {
                column_major[k] = m[16 * j + size_t(k)];
                if (!std::isfinite(column_major[k])) fail(what + ": matrix " + std::to_string(j) + " is not finite");
            }
            skin.inverse_bind[j] = Affine3f::from_column_major(column_major);
        }
    }
    read_influences(primitive, name, vertex_count, skin);
    scene.animation.skins.push_back(std::move(skin));
}

void GltfReader::account_animation(size_t count, size_t element_size) {
    const std::string what = path_ + ": animation data (tracks per channel, deformed meshes per node)";
    animation_bytes_ += checked_array_bytes(what, count, element_size);
    checked_array_bytes(what, animation_bytes_, 1);
}

void GltfReader::finish_animation(Scene& scene) const {
    Animation& animation = scene.animation;
    if (animation.empty()) {
        animation = Animation{};  // nodes alone move nothing: a still scene
        return;
    }
    if (has_keys_) {
        animation.start = key_start_;
        animation.end = key_end_;
    }
    animation.clips = clips_;
    animation.clip = clips_.empty() ? std::string() : clips_[chosen_animation()];
}

Scene GltfReader::read() {
    Scene scene;
    scene.source = path_;
    convert_materials(scene);
    on_path_.assign(model_.nodes.size(), 0);
    node_parent_.assign(model_.nodes.size(), -1);
    animation_node_.assign(model_.nodes.size(), -1);
    for (size_t i = 0; i < model_.nodes.size(); ++i)
        for (int child : model_.nodes[i].children)
            if (child >= 0 && size_t(child) < model_.nodes.size() && node_parent_[size_t(child)] < 0 && size_t(child) != i)
                node_parent_[size_t(child)] = int(i);
    read_animation();

    // The default scene, else scene 0, else every root node.
    std::vector<int> roots;
    if (!model_.scenes.empty()) {
        int index = model_.defaultScene;
        if (index < 0 || size_t(index) >= model_.scenes.size()) index = 0;
        roots = model_.scenes[size_t(index)].nodes;
    } else {
        std::vector<char> is_child(model_.nodes.size(), 0);
        for (const auto& node : model_.nodes)
            for (int child : node.children)
                if (child >= 0 && size_t(child) < is_child.size()) is_child[size_t(child)] = 1;
        for (size_t i = 0; i < model_.nodes.size(); ++i)
            if (!is_child[i]) roots.push_back(int(i));
    }
    for (int root : roots) visit_node(root, Affine3f::identity(), scene, 0, false);
    finish_animation(scene);
    return scene;
}

}  // namespace

namespace {

void configure_loader(tinygltf::TinyGLTF& loader, ImageLoaderContext& image_context) {
    loader.SetImageLoader(&keep_encoded_image, &image_context);
    loader.SetFsCallbacks({&regular_file_exists, &unexpanded_path, &read_regular_file, &refuse_write, nullptr});
}

// The parsed model converted, finalised and, when animated, evaluated at its
// start; errors name `path`.
Scene convert_model(const std::string& path, bool ok, const std::string& err, const std::string& warnings,
                    const tinygltf::Model& model, const LoadOptions& options) {
    if (!ok) {
        std::string reason = one_line(err.empty() ? warnings : err + "\n" + warnings);
        throw file_error(path, 0, reason.empty() ? "invalid glTF file" : reason);
    }
    if (!warnings.empty()) warn(path, one_line(warnings));

    Scene scene = GltfReader(path, model, options).read();
    try {
        scene.finalize();
    } catch (const Error& e) {
        throw file_error(path, 0, e.what());
    }
    if (scene.animated()) scene.set_time(scene.animation.start);
    return scene;
}

}  // namespace

Scene load_gltf(const std::string& path, const LoadOptions& options) {
    if (!regular_file_exists(path, nullptr)) throw file_error(path, 0, "cannot open file");
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    ImageLoaderContext image_context{&model};
    configure_loader(loader, image_context);

    std::string err, warnings;
    // A .glb starts with the magic "glTF"; decide by content so a misnamed
    // file still loads.
    bool binary = lowercase_extension(path) == ".glb";
    if (std::FILE* f = std::fopen(path.c_str(), "rb")) {
        char magic[4] = {};
        binary = std::fread(magic, 1, 4, f) == 4 && std::memcmp(magic, "glTF", 4) == 0;
        std::fclose(f);
    }
    bool ok = binary ? loader.LoadBinaryFromFile(&model, &err, &warnings, path)
                     : loader.LoadASCIIFromFile(&model, &err, &warnings, path);
    return convert_model(path, ok, err, warnings, model, options);
}

Scene io::load_gltf_text(const std::string& text, const std::string& name, const LoadOptions& options) {
    tinygltf::Model model;
    tinygltf::TinyGLTF loader;
    ImageLoaderContext image_context{&model};
    configure_loader(loader, image_context);
    std::string err, warnings;
    // No base directory: only data URIs resolve.
    bool ok = loader.LoadASCIIFromString(&model, &err, &warnings, text.data(), unsigned(text.size()), "");
    Scene scene = convert_model(name, ok, err, warnings, model, options);
    scene.source = name;
    return scene;
}

}  // namespace rf
