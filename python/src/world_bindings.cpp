// rayforge.Camera, rayforge.World (open_world, make_world), rayforge.build_bvh.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <memory>

#include "arrays.h"
#include "device_arrays.h"
#include "bindings.h"
#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/scene_io.h"

namespace rf::py {
namespace {

Vec3f vec3(const std::array<float, 3>& a) { return {a[0], a[1], a[2]}; }
std::array<float, 3> array3(Vec3f v) { return {v.x, v.y, v.z}; }

// Per-ray hit records as the dictionary RaycastingScene.cast_rays returns,
// plus the flat triangle index (world.geometry's order).
pyb::dict hit_dict(const World& world, std::span<const Hit> hits, const std::vector<pyb::ssize_t>& leading,
                   std::span<const uint32_t> paged_instances = {}) {
    auto t_hit = output<float>(leading), uvs = output<float>(leading, {2}), normals = output<float>(leading, {3});
    auto triangle_ids = output<uint32_t>(leading), instance_ids = output<uint32_t>(leading),
         primitive_ids = output<uint32_t>(leading);
    const HitOutputs out{t_hit.mutable_data(),  instance_ids.mutable_data(), primitive_ids.mutable_data(),
                         uvs.mutable_data(),    normals.mutable_data(),      triangle_ids.mutable_data()};
    {
        pyb::gil_scoped_release release;
        fill_hit_outputs(world, hits, out, paged_instances);
    }
    pyb::dict d;
    d["t_hit"] = t_hit;
    d["geometry_ids"] = instance_ids;
    d["primitive_ids"] = primitive_ids;
    d["primitive_uvs"] = uvs;
    d["primitive_normals"] = normals;
    d["triangle_ids"] = triangle_ids;
    return d;
}

pyb::dict stats_dict(const WorldStats& s) {
    pyb::dict d;
    d["triangles"] = s.triangles;
    d["host_bytes"] = s.host_bytes;
    d["device_bytes"] = s.device_bytes;
    d["load_ms"] = s.load_ms;
    d["last_commit"] = s.last_commit == CommitKind::None ? "none" : s.last_commit == CommitKind::Build ? "build" : "update";
    d["commit_ms"] = s.commit_ms;
    d["commits"] = s.commits;
    d["accel"] = s.accel.name;
    d["sah_cost"] = s.accel.sah_cost;
    d["nodes"] = s.accel.node_count;
    d["update_method"] = s.update_method;
    return d;
}

pyb::dict update_dict(const UpdateStats& u) {
    pyb::dict d;
    d["updated"] = u.updated;
    d["update_ms"] = u.update_ms;
    d["layout_ms"] = u.layout_ms;
    d["sah_cost"] = u.sah_cost;
    return d;
}

// One mesh from numpy arrays; optional per-vertex normals and uvs, per-triangle material ids.
Mesh mesh_from(const pyb::handle& vertices, const pyb::handle& triangles, const pyb::handle& normals,
               const pyb::handle& uvs, const pyb::handle& material_ids, size_t material_count) {
    Mesh mesh;
    mesh.name = "mesh";
    mesh.positions = vertex_positions(vertices, "vertices");
    mesh.indices = triangle_indices(triangles, mesh.positions.size(), "triangles");
    if (!normals.is_none()) {
        mesh.normals = vertex_positions(normals, "normals");
        if (mesh.normals.size() != mesh.positions.size())
            throw pyb::value_error("normals: expected one per vertex (" + std::to_string(mesh.positions.size()) +
                                   "), got " + std::to_string(mesh.normals.size()));
    }
    if (!uvs.is_none()) {
        const FloatRows rows = float_rows(uvs, 2, "uvs");
        if (rows.rows != mesh.positions.size())
            throw pyb::value_error("uvs: expected one per vertex (" + std::to_string(mesh.positions.size()) +
                                   "), got " + std::to_string(rows.rows));
        for (size_t i = 0; i < rows.rows; ++i) mesh.uvs.push_back({rows.data()[2 * i], rows.data()[2 * i + 1]});
    }
    if (!material_ids.is_none()) {
        const auto ids = pyb::array_t<int64_t, pyb::array::c_style | pyb::array::forcecast>::ensure(material_ids);
        if (!ids || size_t(ids.size()) != mesh.triangle_count())
            throw pyb::value_error("material_ids: expected one integer per triangle (" +
                                   std::to_string(mesh.triangle_count()) + ")");
        for (pyb::ssize_t i = 0; i < ids.size(); ++i) {
            if (ids.data()[i] < 0 || size_t(ids.data()[i]) >= material_count)
                throw pyb::value_error("material_ids: triangle " + std::to_string(i) + " names material " +
                                       std::to_string(ids.data()[i]) + " of " + std::to_string(material_count));
            mesh.material_ids.push_back(uint32_t(ids.data()[i]));
        }
    }
    return mesh;
}

// A material from a dict with the keys of rf::Material's main fields.
Material material_from(const pyb::dict& d) {
    Material m;
    for (const auto& [key, value] : d) {
        const std::string k = key.cast<std::string>();
        if (k == "name") m.name = value.cast<std::string>();
        else if (k == "base_color") m.base_color = vec3(value.cast<std::array<float, 3>>());
        else if (k == "emission") m.emission = vec3(value.cast<std::array<float, 3>>());
        else if (k == "metallic") m.metallic = value.cast<float>();
        else if (k == "roughness") m.roughness = value.cast<float>();
        else if (k == "transmission") m.transmission = value.cast<float>();
        else if (k == "ior") m.ior = value.cast<float>();
        else
            throw pyb::value_error("materials: unknown key '" + k +
                                   "' (known: name, base_color, emission, metallic, roughness, transmission, ior)");
    }
    return m;
}

}  // namespace

WorldOptions world_options(const std::string& device, const std::string& structure, const std::string& builder,
                           const std::string& layout, const std::optional<std::string>& gpu_kernel,
                           const std::optional<std::string>& update, int threads,
                           const std::optional<std::string>& memory_budget) {
    WorldOptions o;
    o.device = parsed("device", [&] { return parse_device(device); });
    o.build.structure = parsed("structure", [&] { return parse_structure(structure); });
    o.build.builder = parsed("builder", [&] { return parse_builder(builder); });
    o.build.layout = parsed("layout", [&] { return parse_layout(layout); });
    if (gpu_kernel) o.build.gpu_kernel = parsed("gpu_kernel", [&] { return parse_gpu_kernel(*gpu_kernel); });
    if (update) o.update.method = parsed("update", [&] { return parse_update_method(*update); });
    o.build.threads = o.paged.threads = thread_count(threads);
    if (memory_budget) {
        const std::optional<size_t> bytes = parse_memory_size(*memory_budget);
        if (!bytes) throw pyb::value_error("memory_budget: '" + *memory_budget + "' is not a size (e.g. 512M, 2G)");
        o.paged.memory_budget = *bytes;
    }
    return o;
}

void fill_hit_outputs(const World& world, std::span<const Hit> hits, const HitOutputs& out,
                      std::span<const uint32_t> paged_instances) {
    const SceneGeometry& g = world.geometry();
    const bool paged = world.paged();
    parallel::for_range(size_t(0), hits.size(), size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const Hit& h = hits[i];
            const bool found = h.found() && (paged || h.prim < g.size());
            const bool mapped = found && !paged;
            out.t[i] = found ? h.t : std::numeric_limits<float>::infinity();
            out.uvs[2 * i] = found ? h.u : 0.0f;
            out.uvs[2 * i + 1] = found ? h.v : 0.0f;
            out.geometry_ids[i] = mapped                               ? g.triangle_instance[h.prim]
                                  : found && !paged_instances.empty() ? paged_instances[i]
                                                                      : kInvalidId;
            out.primitive_ids[i] = mapped ? g.local_triangle[h.prim] : kInvalidId;
            if (out.triangle_ids) out.triangle_ids[i] = found ? h.prim : kInvalidId;
            if (!out.normals) continue;
            const Vec3f n = mapped  ? normalize(g.triangles[h.prim].geometric_normal())
                            : found ? Vec3f(std::numeric_limits<float>::quiet_NaN())
                                    : Vec3f(0.0f);
            out.normals[3 * i] = n.x, out.normals[3 * i + 1] = n.y, out.normals[3 * i + 2] = n.z;
        }
    });
}

void bind_camera(pyb::module_& m) {
    pyb::class_<Camera>(m, "Camera", "A perspective camera: eye, target, up and the vertical field of view in degrees.")
        .def(pyb::init([](std::array<float, 3> eye, std::array<float, 3> target, std::array<float, 3> up, float fov) {
                 Camera c;
                 c.eye = vec3(eye), c.target = vec3(target), c.up = vec3(up), c.vfov_degrees = fov;
                 return c;
             }),
             pyb::arg("eye") = std::array<float, 3>{0, 0, 5}, pyb::arg("target") = std::array<float, 3>{0, 0, 0},
             pyb::arg("up") = std::array<float, 3>{0, 1, 0}, pyb::arg("fov") = 45.0f)
        .def_static("parse", [](const std::string& text) { return parsed("camera", [&] { return parse_camera(text); }); },
                    pyb::arg("text"), "The CLI's --camera form 'ex,ey,ez,tx,ty,tz,ux,uy,uz,fov'.")
        .def_property("eye", [](const Camera& c) { return array3(c.eye); },
                      [](Camera& c, std::array<float, 3> v) { c.eye = vec3(v); }, "position (x, y, z)")
        .def_property("target", [](const Camera& c) { return array3(c.target); },
                      [](Camera& c, std::array<float, 3> v) { c.target = vec3(v); }, "the point looked at")
        .def_property("up", [](const Camera& c) { return array3(c.up); },
                      [](Camera& c, std::array<float, 3> v) { c.up = vec3(v); }, "the up direction")
        .def_readwrite("fov", &Camera::vfov_degrees, "vertical field of view, degrees")
        .def_readwrite("aperture_radius", &Camera::aperture_radius, "thin lens radius (0: pinhole)")
        .def_readwrite("focus_distance", &Camera::focus_distance, "0: the distance from eye to target")
        .def("__str__", [](const Camera& c) { return to_string(c); })
        .def("__repr__", [](const Camera& c) { return "rayforge.Camera.parse('" + to_string(c) + "')"; });
}

void bind_world(pyb::module_& m) {
    pyb::class_<World, std::shared_ptr<World>>(
        m, "World",
        "A scene with its triangles and acceleration structure on one device, kept current as time moves "
        "(docs/world.md). Made by open_world or make_world.")
        .def_property_readonly("device", [](const World& w) { return to_string(w.device()); },
                               "where the structure lives and queries run: 'cpu' or 'cuda:N'")
        .def_property_readonly("paged", &World::paged, "whether the world reads a paged .rfpack file")
        .def_property_readonly("animated", &World::animated, "whether set_time moves it")
        .def_property_readonly("time", &World::time, "the time the world was last set to, seconds")
        .def_property_readonly("time_range",
                               [](const World& w) {
                                   const TimeRange r = w.time_range();
                                   return pyb::make_tuple(r.start, r.end, r.frames_per_second);
                               },
                               "(start, end, frames per second) of the animation")
        .def_property_readonly("bounds",
                               [](const World& w) {
                                   const Box3f b = w.bounds();
                                   return pyb::make_tuple(array3(b.lo), array3(b.hi));
                               },
                               "((min x, y, z), (max x, y, z)) of the triangles now")
        .def_property_readonly("notes", &World::notes, "defaults the device replaced (a scene file's update method)")
        .def("camera", &World::camera, "The scene's own camera at the current time (or one framing it).")
        .def("stats", [](const World& w) { return stats_dict(w.stats()); },
             "triangles, host_bytes, device_bytes, load_ms, last_commit, commit_ms, commits, accel, sah_cost, nodes, "
             "update_method")
        .def("commit",
             [](World& w) {
                 WorldStats s;
                 {
                     pyb::gil_scoped_release release;
                     s = w.commit();
                 }
                 return stats_dict(s);
             },
             "Builds the structure now (it is built at the first query or renderer otherwise).")
        .def("set_time",
             [](World& w, float t) {
                 UpdateStats u;
                 {
                     pyb::gil_scoped_release release;
                     u = w.set_time(t);
                 }
                 return update_dict(u);
             },
             pyb::arg("t"), "Moves an animated world to time t (seconds); the structure follows.")
        .def("set_vertices",
             [](World& w, uint32_t mesh, const pyb::handle& positions) {
                 if (w.paged()) throw pyb::value_error("set_vertices: a paged world's geometry is in its file");
                 if (mesh >= w.scene().meshes.size())
                     throw pyb::value_error("mesh: " + std::to_string(mesh) + " of " +
                                            std::to_string(w.scene().meshes.size()) + " meshes");
                 std::vector<Vec3f> p = vertex_positions(positions, "positions");
                 if (p.size() != w.scene().meshes[mesh].positions.size())
                     throw pyb::value_error("positions: expected " +
                                            std::to_string(w.scene().meshes[mesh].positions.size()) + " rows, got " +
                                            std::to_string(p.size()));
                 UpdateStats u;
                 {
                     pyb::gil_scoped_release release;
                     w.scene().meshes[mesh].positions = std::move(p);
                     u = w.geometry_replaced(GeometryChange{{mesh}, {}, false});
                 }
                 return update_dict(u);
             },
             pyb::arg("mesh"), pyb::arg("positions"),
             "New vertex positions for one mesh; the structure follows by the world's update method (refit with "
             "update='refit'), by a rebuild otherwise.")
        .def("trace",
             [](const World& w, const pyb::handle& rays, float tnear, float tfar) {
                 const FloatRows rows = float_rows(rays, 6, "rays");
                 RawArray<Hit> hits(rows.rows);
                 RawArray<uint32_t> instances(w.paged() ? rows.rows : 0);
                 {
                     pyb::gil_scoped_release release;
                     const RawArray<Ray> r = to_rays(rows, tnear, tfar);
                     if (w.paged()) w.paged_scene().intersect(r, hits, instances);
                     else w.intersect(r, hits);
                 }
                 return hit_dict(w, hits, rows.leading, instances);
             },
             pyb::arg("rays"), pyb::arg("tnear") = 0.0f, pyb::arg("tfar") = std::numeric_limits<float>::infinity(),
             "Closest hits of (..., 6) rays: t_hit, geometry_ids (instance; paged: the file's instance), primitive_ids "
             "(triangle of its mesh), primitive_uvs, primitive_normals, triangle_ids (the world's flat index; paged: "
             "the paged triangle id).")
        .def("occluded",
             [](const World& w, const pyb::handle& rays, float tnear, float tfar) {
                 const FloatRows rows = float_rows(rays, 6, "rays");
                 auto out = output<bool>(rows.leading);
                 const std::span<uint8_t> blocked = bool_bytes(out);  // written in place
                 {
                     pyb::gil_scoped_release release;
                     w.occluded(to_rays(rows, tnear, tfar), blocked);
                 }
                 return out;
             },
             pyb::arg("rays"), pyb::arg("tnear") = 0.0f, pyb::arg("tfar") = std::numeric_limits<float>::infinity(),
             "Whether anything lies on each ray between tnear and tfar.")
        .def(
            "trace_on_device",
            [](const World& w, const pyb::handle& rays, const pyb::handle& hits, const std::optional<intptr_t>& stream) {
                trace_device_arrays(w, rays, &hits, nullptr, stream);
            },
            pyb::arg("rays"), pyb::arg("hits"), pyb::kw_only(), pyb::arg("stream") = pyb::none(),
            "Closest hits of rays in CUDA memory, written into CUDA memory (objects with __cuda_array_interface__ "
            "or __dlpack__): rays (n, 8) float32 [ox, oy, oz, tmin, dx, dy, dz, tmax], hits (n, 4) 4-byte "
            "[t, u, v, prim] (prim as uint32 bits, 0xFFFFFFFF on a miss); stream a cudaStream_t as an int "
            "(default: the rays' producer stream, else the default stream). The world must be on that device.")
        .def(
            "occluded_on_device",
            [](const World& w, const pyb::handle& rays, const pyb::handle& occluded, const std::optional<intptr_t>& stream) {
                trace_device_arrays(w, rays, nullptr, &occluded, stream);
            },
            pyb::arg("rays"), pyb::arg("occluded"), pyb::kw_only(), pyb::arg("stream") = pyb::none(),
            "Any hits of rays in CUDA memory (as trace_on_device) into occluded (n,) uint8 or bool in CUDA memory.");

    m.def(
        "open_world",
        [](const std::string& path, const std::string& device, const std::string& structure, const std::string& builder,
           const std::string& layout, const std::optional<std::string>& gpu_kernel,
           const std::optional<std::string>& update, int threads, const std::optional<std::string>& memory_budget,
           const std::string& animation) {
            const WorldOptions o = world_options(device, structure, builder, layout, gpu_kernel, update, threads,
                                                 memory_budget);
            LoadOptions load;
            load.animation = animation;
            pyb::gil_scoped_release release;
            return std::shared_ptr<World>(open_world(path, o, load));
        },
        pyb::arg("path"), pyb::kw_only(), pyb::arg("device") = "cpu", pyb::arg("structure") = "bvh",
        pyb::arg("builder") = "binned", pyb::arg("layout") = "bvh8", pyb::arg("gpu_kernel") = pyb::none(),
        pyb::arg("update") = pyb::none(), pyb::arg("threads") = 0, pyb::arg("memory_budget") = pyb::none(),
        pyb::arg("animation") = "",
        "Opens a scene file (.obj, .ply, .gltf, .glb, .aff, .json), builtin:NAME or a paged .rfpack as a World.");

    m.def(
        "make_world",
        [](const pyb::handle& vertices, const pyb::handle& triangles, const pyb::handle& normals,
           const pyb::handle& uvs, const pyb::handle& material_ids, const std::optional<pyb::list>& materials,
           const std::optional<std::array<float, 3>>& environment, const std::string& device,
           const std::string& structure, const std::string& builder, const std::string& layout,
           const std::optional<std::string>& gpu_kernel, const std::optional<std::string>& update, int threads) {
            Scene scene;
            if (materials) {
                for (const pyb::handle& item : *materials) {
                    try {
                        scene.materials.push_back(material_from(item.cast<pyb::dict>()));
                    } catch (const pyb::cast_error&) {
                        throw pyb::type_error("materials: expected dicts of a name (str), base_color and emission "
                                              "(3 floats), metallic, roughness, transmission and ior (floats)");
                    }
                }
            }
            if (scene.materials.empty()) scene.materials.push_back(Material{});
            scene.meshes.push_back(mesh_from(vertices, triangles, normals, uvs, material_ids, scene.materials.size()));
            if (environment) scene.environment.color = vec3(*environment);
            const WorldOptions o = world_options(device, structure, builder, layout, gpu_kernel, update, threads, {});
            pyb::gil_scoped_release release;
            return std::shared_ptr<World>(make_world(std::move(scene), o));
        },
        pyb::arg("vertices"), pyb::arg("triangles"), pyb::kw_only(), pyb::arg("normals") = pyb::none(),
        pyb::arg("uvs") = pyb::none(), pyb::arg("material_ids") = pyb::none(), pyb::arg("materials") = pyb::none(),
        pyb::arg("environment") = pyb::none(), pyb::arg("device") = "cpu", pyb::arg("structure") = "bvh",
        pyb::arg("builder") = "binned", pyb::arg("layout") = "bvh8", pyb::arg("gpu_kernel") = pyb::none(),
        pyb::arg("update") = pyb::none(), pyb::arg("threads") = 0,
        "A World of one mesh from numpy arrays: vertices (n, 3) float32, triangles (m, 3) integers; optional "
        "normals (n, 3), uvs (n, 2), material_ids (m,) into materials (a list of dicts with base_color, "
        "emission, metallic, roughness, transmission, ior), and a constant environment colour.");

    m.def(
        "load_mesh",
        [](const std::string& path) {
            Scene scene;
            {
                pyb::gil_scoped_release release;
                scene = load_scene(path);
            }
            size_t vertex_count = 0, index_count = 0;
            for (const Instance& inst : scene.instances) {
                vertex_count += scene.meshes[inst.mesh].positions.size();
                index_count += scene.meshes[inst.mesh].indices.size();
            }
            if (vertex_count > size_t(UINT32_MAX))
                throw Error("load_mesh: " + path + " has " + std::to_string(vertex_count) +
                            " vertices over its instances, more than uint32 indices address");
            auto vertices = output<float>({pyb::ssize_t(vertex_count)}, {3});
            auto triangles = output<uint32_t>({pyb::ssize_t(index_count / 3)}, {3});
            float* v = vertices.mutable_data();
            uint32_t* t = triangles.mutable_data();
            uint32_t base = 0;
            for (const Instance& inst : scene.instances) {
                const Mesh& mesh = scene.meshes[inst.mesh];
                for (const Vec3f& p : mesh.positions) {
                    const Vec3f w = inst.transform.transform_point(p);
                    *v++ = w.x, *v++ = w.y, *v++ = w.z;
                }
                for (const uint32_t i : mesh.indices) *t++ = base + i;
                base += uint32_t(mesh.positions.size());
            }
            return pyb::make_tuple(vertices, triangles);
        },
        pyb::arg("path"),
        "Loads a scene file (.obj, .ply, .gltf, .glb, .aff, .json) or builtin:NAME as one triangle mesh in world "
        "space: (vertices (n, 3) float32, triangles (m, 3) uint32), every instance's triangles (hidden ones "
        "included) in instance order; for RaycastingScene.add_triangles or make_world.");

    m.def(
        "build_bvh",
        [](const pyb::handle& vertices, const pyb::handle& triangles, const std::string& builder, int leaf_size,
           int threads) {
            const std::vector<Vec3f> p = vertex_positions(vertices, "vertices");
            const std::vector<uint32_t> idx = triangle_indices(triangles, p.size(), "triangles");
            BuildOptions o;
            o.builder = parsed("builder", [&] { return parse_builder(builder); });
            o.max_leaf_size = leaf_size;
            o.threads = thread_count(threads);
            std::vector<Triangle> tris(idx.size() / 3);
            for (size_t t = 0; t < tris.size(); ++t) tris[t] = {p[idx[3 * t]], p[idx[3 * t + 1]], p[idx[3 * t + 2]]};
            Bvh bvh;
            {
                pyb::gil_scoped_release release;
                bvh = parsed("build_bvh", [&] { return build_bvh(tris, o); });
            }
            // Nodes as a structured array: the canonical 32-byte nodes (include/rayforge/accel/bvh/bvh.h).
            pyb::dict layout;
            layout["names"] = pyb::make_tuple("lo", "hi", "first", "count");
            layout["formats"] = pyb::make_tuple("(3,)f4", "(3,)f4", "u4", "u4");
            layout["offsets"] = pyb::make_tuple(0, 12, 24, 28);
            layout["itemsize"] = 32;
            pyb::array nodes(pyb::dtype::from_args(layout), std::vector<pyb::ssize_t>{pyb::ssize_t(bvh.nodes.size())});
            std::memcpy(nodes.mutable_data(), bvh.nodes.data(), bvh.nodes.size() * sizeof(BvhNode));
            pyb::array_t<uint32_t> prims(pyb::ssize_t(bvh.prim_indices.size()));
            std::copy(bvh.prim_indices.begin(), bvh.prim_indices.end(), prims.mutable_data());
            pyb::dict d;
            d["nodes"] = nodes;
            d["prim_indices"] = prims;
            d["sah_cost"] = bvh.nodes.empty() ? 0.0 : bvh.sah_cost();
            d["leaves"] = bvh.leaf_count();
            return d;
        },
        pyb::arg("vertices"), pyb::arg("triangles"), pyb::kw_only(), pyb::arg("builder") = "binned",
        pyb::arg("leaf_size") = 4, pyb::arg("threads") = 0,
        "The canonical binary BVH of a builder over triangles: nodes (a structured array: lo, hi, first, count; "
        "an inner node has count 0 and children first, first + 1), prim_indices, sah_cost, leaves.");
}

}  // namespace rf::py
