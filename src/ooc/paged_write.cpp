// Writing paged scenes through the public API: converting a scene in memory,
// and generating a procedural one straight into a paged (or OBJ) file.
#include <cstdio>
#include <fstream>

#include "io/path_utils.h"
#include "ooc/convert_scene.h"
#include "ooc/obj_stream_convert.h"
#include "rayforge/io/scene_io.h"
#include "ooc/generate/massive_scene.h"
#include "rayforge/core/error.h"
#include "rayforge/ooc/paged_scene.h"

namespace rf {

PagedTopLevel parse_paged_top_level(const std::string& name) {
    if (name == "bvh") return PagedTopLevel::WideBvh;
    if (name == "grid") return PagedTopLevel::Grid;
    throw Error("unknown paged top level '" + name + "' (bvh or grid)");
}

std::string to_string(PagedTopLevel top) { return top == PagedTopLevel::Grid ? "grid" : "bvh"; }

PagedCodec parse_paged_codec(const std::string& name) {
    if (name == "meshopt") return PagedCodec::Meshopt;
    if (name == "zstd") return PagedCodec::Zstd;
    if (name == "none") return PagedCodec::None;
    throw Error("unknown page codec '" + name + "' (meshopt, zstd or none)");
}

std::string to_string(PagedCodec codec) {
    return codec == PagedCodec::Meshopt ? "meshopt" : codec == PagedCodec::Zstd ? "zstd" : "none";
}

PagedAttributes parse_paged_attributes(const std::string& name) {
    if (name == "shared") return PagedAttributes::Shared;
    if (name == "full") return PagedAttributes::Full;
    if (name == "compact") return PagedAttributes::Compact;
    throw Error("unknown attribute format '" + name + "' (shared, full or compact)");
}

std::string to_string(PagedAttributes attributes) {
    return attributes == PagedAttributes::Shared ? "shared" : attributes == PagedAttributes::Full ? "full" : "compact";
}

namespace {

pack::PackWriterOptions writer_options(const PagedWriteOptions& o) {
    pack::PackWriterOptions w;
    w.codec = o.codec == PagedCodec::Meshopt ? pack::Codec::Meshopt
              : o.codec == PagedCodec::Zstd  ? pack::Codec::Zstd
                                             : pack::Codec::None;
    w.zstd_level = o.zstd_level;
    w.attribute_format = o.attributes == PagedAttributes::Shared ? pack::AttributeFormat::Shared
                         : o.attributes == PagedAttributes::Full ? pack::AttributeFormat::Full
                                                                 : pack::AttributeFormat::Compact;
    w.attribute_page_bytes = o.attribute_page_bytes;
    w.quads_per_page = o.quads_per_page;
    w.top_level = o.top_level == PagedTopLevel::Grid ? pack::TopLevel::Grid : pack::TopLevel::WideBvh;
    w.grid_resolution = o.grid_resolution;
    w.flatten_instances = o.flatten_instances;
    w.threads = o.threads;
    return w;
}

PagedWriteReport to_report(const pack::PackSummary& s, std::vector<std::string> notes) {
    PagedWriteReport r;
    r.triangles = s.triangles;
    r.instances = s.instances;
    r.instanced_triangles = s.instanced_triangles;
    r.quads = s.quads;
    r.paired_triangles = s.paired_triangles;
    r.geometry_pages = s.geometry_pages;
    r.attribute_pages = s.attribute_pages;
    r.texture_pages = s.texture_pages;
    r.middle_nodes = s.middle_nodes;
    r.top_nodes = s.top_nodes;
    r.file_bytes = s.file_bytes;
    r.geometry_bytes = s.geometry_bytes;
    r.attribute_bytes = s.attribute_bytes;
    r.texture_bytes = s.texture_bytes;
    r.resident_bytes = s.resident_bytes;
    r.decoded_bytes = s.decoded_bytes;
    r.max_quantisation_error = s.max_quantisation_error;
    r.notes = std::move(notes);
    return r;
}

pack::GenerateOptions generator_options(const GenerateOptions& o) {
    pack::GenerateOptions g;
    g.name = o.name;
    g.triangles = o.triangles;
    g.seed = o.seed;
    g.statue_dir = o.statue_dir;
    g.max_object_triangles = o.max_object_triangles;
    g.instanced_triangles = o.instanced_triangles;
    return g;
}

// Shading records of a generated object (already in world space).
std::vector<ShadingTriangle> shading_of(const pack::GeneratedObject& object) {
    std::vector<ShadingTriangle> shading(object.triangle_count());
    const Affine3f identity = Affine3f::identity();
    for (size_t t = 0; t < shading.size(); ++t) {
        const uint32_t* idx = &object.indices[3 * t];
        const Triangle tri{object.positions[idx[0]], object.positions[idx[1]], object.positions[idx[2]]};
        shading[t] = make_shading_triangle(object.normals, object.uvs, identity, tri, idx, object.material_ids[t]);
    }
    return shading;
}

// The generated objects as an OBJ file (positions, normals, uvs, one group
// per object, materials as usemtl names m0, m1, ...), streamed.
class ObjSink {
public:
    explicit ObjSink(const std::string& path) : out_(path) {
        if (!out_) throw file_error(path, 0, "cannot create");
        out_ << "# rayforge generate\n";
    }
    void add(const pack::GeneratedObject& o) {
        out_ << "o object" << objects_++ << '\n';
        for (const Vec3f& p : o.positions) out_ << "v " << p.x << ' ' << p.y << ' ' << p.z << '\n';
        for (const Vec3f& n : o.normals) out_ << "vn " << n.x << ' ' << n.y << ' ' << n.z << '\n';
        for (const Vec2f& t : o.uvs) out_ << "vt " << t.x << ' ' << 1.0f - t.y << '\n';
        uint32_t material = ~0u;
        for (size_t t = 0; t < o.triangle_count(); ++t) {
            if (o.material_ids[t] != material) {
                material = o.material_ids[t];
                out_ << "usemtl m" << material << '\n';
            }
            out_ << 'f';
            for (int k = 0; k < 3; ++k) {
                const uint64_t v = base_ + o.indices[3 * t + size_t(k)] + 1;
                out_ << ' ' << v << '/' << v << '/' << v;
            }
            out_ << '\n';
        }
        base_ += o.positions.size();
        triangles_ += o.triangle_count();
        if (!out_) throw Error("generate: writing the OBJ file failed (disk full?)");
    }
    uint64_t bytes() { return uint64_t(out_.tellp()); }
    [[nodiscard]] uint64_t triangles() const { return triangles_; }

private:
    std::ofstream out_;
    uint64_t base_ = 0, objects_ = 0, triangles_ = 0;
};

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

bool is_obj_file(const std::string& path) { return io::lowercase_extension(path) == ".obj"; }

}  // namespace

PagedWriteReport convert_to_paged(const Scene& scene, const std::string& path, const PagedWriteOptions& options,
                                  const ProgressCallback& progress) {
    pack::ConvertResult r = pack::convert_scene(scene, path, writer_options(options), progress);
    return to_report(r.summary, std::move(r.notes));
}

PagedWriteReport convert_file_to_paged(const std::string& scene_file, const std::string& path,
                                       const PagedWriteOptions& options, const ConvertInputOptions& input,
                                       const ProgressCallback& progress) {
    if (!is_obj_file(scene_file)) {
        PagedWriteReport r = convert_to_paged(load_scene(scene_file), path, options, progress);
        r.notes.push_back("the input was loaded in core (convert streams .obj files only)");
        return r;
    }
    pack::StreamConvertOptions stream;
    stream.memory_budget = size_t(input.memory_budget);
    stream.temp_dir = input.temp_dir;
    pack::StreamConvertResult s =
        pack::convert_obj_streaming(scene_file, path, writer_options(options), stream, progress);
    PagedWriteReport r = to_report(s.convert.summary, std::move(s.convert.notes));
    r.streamed = true;
    r.objects = s.objects;
    r.scratch_bytes = s.scratch_bytes;
    r.max_object_triangles = s.budget.max_object_triangles;
    return r;
}

std::vector<std::string> generated_scene_names() { return pack::generator_names(); }

PagedWriteReport generate_paged_scene(const GenerateOptions& options, const std::string& path,
                                      const PagedWriteOptions& write, const ProgressCallback& progress) {
    const pack::GenerateOptions g = generator_options(options);
    const pack::GeneratedLook look = pack::generated_look(g);
    if (ends_with(path, ".obj")) {
        ObjSink obj(path);
        pack::generate_scene(g, [&](const pack::GeneratedObject& o) { obj.add(o); }, progress);
        PagedWriteReport r;
        r.triangles = obj.triangles();
        r.file_bytes = obj.bytes();
        r.notes.push_back("OBJ output keeps geometry, normals, uvs and material names, not the materials themselves");
        return r;
    }
    pack::PackWriter writer(path, writer_options(write));
    for (const Texture& t : look.textures) writer.add_texture(t);
    for (const Material& m : look.materials) writer.add_material(ShadingMaterial::from(m));
    for (const Light& l : look.lights) writer.add_light(l);
    writer.set_camera(look.camera);
    writer.set_environment(look.environment);
    const auto report = [&](double f) {
        if (progress) progress(0.97 * f);
    };
    const pack::InstanceSink instances{
        [&](const pack::GeneratedObject& o) {
            const std::vector<ShadingTriangle> shading = shading_of(o);
            return writer.add_instanced_object({o.positions, o.indices, shading});
        },
        [&](uint32_t prototype, const Affine3f& m) { writer.add_instance(prototype, m); }};
    pack::generate_scene(g, [&](const pack::GeneratedObject& o) {
        const std::vector<ShadingTriangle> shading = shading_of(o);
        writer.add_object({o.positions, o.indices, shading});
    }, report, &instances);
    const pack::PackSummary summary = writer.finish([&](double f) {
        if (progress) progress(0.97 + 0.03 * f);
    });
    return to_report(summary, {});
}

Scene generate_scene(const GenerateOptions& options) {
    const pack::GenerateOptions g = generator_options(options);
    pack::GeneratedLook look = pack::generated_look(g);
    Scene scene;
    scene.source = "generate:" + options.name;
    scene.materials = std::move(look.materials);
    scene.textures = std::move(look.textures);
    scene.lights = std::move(look.lights);
    scene.environment = look.environment;
    scene.camera = look.camera;
    const auto add_mesh = [&](const pack::GeneratedObject& o) {
        Mesh mesh;
        mesh.name = "object" + std::to_string(scene.meshes.size());
        mesh.positions = o.positions;
        mesh.normals = o.normals;
        mesh.uvs = o.uvs;
        mesh.indices = o.indices;
        mesh.material_ids = o.material_ids;
        scene.meshes.push_back(std::move(mesh));
        return uint32_t(scene.meshes.size() - 1);
    };
    const pack::InstanceSink instances{add_mesh, [&](uint32_t mesh, const Affine3f& m) {
                                           scene.instances.push_back({mesh, m, true});
                                       }};
    pack::generate_scene(
        g, [&](const pack::GeneratedObject& o) { scene.instances.push_back({add_mesh(o), Affine3f::identity(), true}); },
        {}, &instances);
    scene.finalize();
    return scene;
}

}  // namespace rf
