// rayforge.RaycastingScene: Open3D 0.18's RaycastingScene (its method and
// argument names, shapes, dtypes and dictionary keys), over a World (closest
// and any hit, on the CPU or a CUDA device) and MeshQueries (every hit along
// a ray, closest points, winding numbers; CPU). Geometry added with
// add_triangles is one mesh of the world's scene each; the world and the
// queries are made at the first query after a change. Queries from several
// Python threads run at once (a shared lock; the GIL is released); adding or
// refitting geometry waits for them.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <shared_mutex>

#include "arrays.h"
#include "device_arrays.h"
#include "bindings.h"
#include "core/parallel.h"
#include "rayforge/accel/mesh_queries.h"

namespace rf::py {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// How compute_signed_distance and compute_occupancy decide inside.
enum class Sign { Winding, Parity };

Sign parse_sign(const std::string& text) {
    if (text == "winding") return Sign::Winding;
    if (text == "parity") return Sign::Parity;
    throw pyb::value_error("sign: expected 'winding' (robust, the default) or 'parity' (Open3D's), got '" + text + "'");
}

// Directions of the parity test's rays: fixed, irrational-looking (no axis
// and no diagonal, which meshes' edges often follow), spread over the sphere.
Vec3f parity_direction(int k) {
    const float golden = 2.39996323f;
    const float z = 1.0f - (2.0f * float(k) + 1.0f) / 31.0f;
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    const float phi = 0.7f + golden * float(k);
    return normalize(Vec3f(r * std::cos(phi), r * std::sin(phi), z + 0.013f));
}

class RaycastingScene {
public:
    RaycastingScene(int nthreads, const std::string& device, const std::string& builder, const std::string& layout)
        : nthreads_(thread_count(nthreads)) {
        options_ = world_options(device, "bvh", builder, layout, std::nullopt, "refit", nthreads_, std::nullopt);
        check_world_options(options_);
        scene_.materials.push_back(Material{});
    }

    uint32_t add_triangles(const pyb::handle& vertices, const pyb::handle& triangles) {
        Mesh mesh;
        mesh.name = "geometry" + std::to_string(scene_.meshes.size());
        mesh.positions = vertex_positions(vertices, "vertex_positions");
        mesh.indices = triangle_indices(triangles, mesh.positions.size(), "triangle_indices");
        mesh.material_ids.assign(mesh.triangle_count(), 0);
        pyb::gil_scoped_release release;
        std::unique_lock<std::shared_mutex> lock(mutex_);
        const uint32_t id = uint32_t(scene_.meshes.size());
        scene_.meshes.push_back(std::move(mesh));
        scene_.instances.push_back({id, Affine3f::identity()});
        world_.reset();  // made again, with the new geometry, at the next query
        queries_.reset();
        return id;
    }

    void refit(uint32_t geometry_id, const pyb::handle& vertices) {
        if (geometry_id >= scene_.meshes.size())
            throw pyb::value_error("geometry_id: " + std::to_string(geometry_id) + " of " +
                                   std::to_string(scene_.meshes.size()) + " geometries");
        std::vector<Vec3f> p = vertex_positions(vertices, "vertex_positions");
        if (p.size() != scene_.meshes[geometry_id].positions.size())
            throw pyb::value_error("vertex_positions: geometry " + std::to_string(geometry_id) + " has " +
                                   std::to_string(scene_.meshes[geometry_id].positions.size()) + " vertices, got " +
                                   std::to_string(p.size()));
        pyb::gil_scoped_release release;
        std::unique_lock<std::shared_mutex> lock(mutex_);
        scene_.meshes[geometry_id].positions = p;
        if (!world_) return;
        world_->scene().meshes[geometry_id].positions = std::move(p);
        world_->geometry_replaced(GeometryChange{{geometry_id}, {}, false});  // the world's update method: refit
        if (queries_) queries_->refit(world_->geometry().triangles);
    }

    pyb::dict cast_rays(const pyb::handle& rays, int nthreads) {
        const FloatRows rows = float_rows(rays, 6, "rays");
        auto t_hit = output<float>(rows.leading), uvs = output<float>(rows.leading, {2}),
             normals = output<float>(rows.leading, {3});
        auto geometry_ids = output<uint32_t>(rows.leading), primitive_ids = output<uint32_t>(rows.leading);
        const HitOutputs out{t_hit.mutable_data(), geometry_ids.mutable_data(), primitive_ids.mutable_data(),
                             uvs.mutable_data(), normals.mutable_data(), nullptr};
        const Reading r = read(nthreads, false);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            r.run([&] {
                RawArray<Hit> hits(rows.rows);
                world_->intersect(to_rays(rows, 0.0f, kInfinity), hits);
                fill_hits(hits, out);
            });
        }
        pyb::dict d;
        d["t_hit"] = t_hit;
        d["geometry_ids"] = geometry_ids;
        d["primitive_ids"] = primitive_ids;
        d["primitive_uvs"] = uvs;
        d["primitive_normals"] = normals;
        return d;
    }

    pyb::array test_occlusions(const pyb::handle& rays, float tnear, float tfar, int nthreads) {
        const FloatRows rows = float_rows(rays, 6, "rays");
        auto out = output<bool>(rows.leading);
        const std::span<uint8_t> blocked = bool_bytes(out);  // written in place
        const Reading r = read(nthreads, false);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            r.run([&] { world_->occluded(to_rays(rows, tnear, tfar), blocked); });
        }
        return out;
    }

    // Device arrays in place (device_arrays.h); the world must live on their device.
    void trace_on_device(const pyb::handle& rays, const pyb::handle* hits, const pyb::handle* occluded,
                         const std::optional<intptr_t>& stream) {
        (void)read(0, false);
        std::shared_lock<std::shared_mutex> lock;
        {
            pyb::gil_scoped_release release;
            lock = ready();
        }
        trace_device_arrays(*world_, rays, hits, occluded, stream);
    }

    pyb::array count_intersections(const pyb::handle& rays, int nthreads) {
        const FloatRows rows = float_rows(rays, 6, "rays");
        auto out = output<int32_t>(rows.leading);
        int32_t* o = out.mutable_data();
        const Reading r = read(nthreads, true);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            std::vector<uint32_t> counts(rows.rows);
            r.run([&] { queries_->count_intersections(to_rays(rows, 0.0f, kInfinity), counts); });
            std::copy(counts.begin(), counts.end(), o);
        }
        return out;
    }

    pyb::dict list_intersections(const pyb::handle& rays, int nthreads) {
        const FloatRows rows = float_rows(rays, 6, "rays");
        AllHits all;
        const Reading r = read(nthreads, true);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            r.run([&] { queries_->list_intersections(to_rays(rows, 0.0f, kInfinity), all); });
        }
        const pyb::ssize_t n = pyb::ssize_t(all.hits.size());
        pyb::array_t<uint32_t> splits(pyb::ssize_t(all.ray_splits.size())), ray_ids(n), geometry_ids(n),
            primitive_ids(n);
        pyb::array_t<float> t_hit(n), uvs({n, pyb::ssize_t(2)});
        std::copy(all.ray_splits.begin(), all.ray_splits.end(), splits.mutable_data());
        std::copy(all.ray_ids.begin(), all.ray_ids.end(), ray_ids.mutable_data());
        const HitOutputs out{t_hit.mutable_data(), geometry_ids.mutable_data(), primitive_ids.mutable_data(),
                             uvs.mutable_data(), nullptr, nullptr};
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            r.run([&] { fill_hits(all.hits, out); });
        }
        pyb::dict d;
        d["ray_splits"] = splits;
        d["ray_ids"] = ray_ids;
        d["t_hit"] = t_hit;
        d["geometry_ids"] = geometry_ids;
        d["primitive_ids"] = primitive_ids;
        d["primitive_uvs"] = uvs;
        return d;
    }

    pyb::dict compute_closest_points(const pyb::handle& query_points, int nthreads) {
        const FloatRows rows = float_rows(query_points, 3, "query_points");
        auto points = output<float>(rows.leading, {3}), uvs = output<float>(rows.leading, {2}),
             normals = output<float>(rows.leading, {3});
        auto geometry_ids = output<uint32_t>(rows.leading), primitive_ids = output<uint32_t>(rows.leading);
        std::vector<float> distance_unused(rows.rows);
        const HitOutputs out{distance_unused.data(), geometry_ids.mutable_data(), primitive_ids.mutable_data(),
                             uvs.mutable_data(), normals.mutable_data(), nullptr};
        float* p = points.mutable_data();
        const Reading r = read(nthreads, true);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            r.run([&] {
                std::vector<ClosestPoint> closest(rows.rows);
                queries_->closest_points(as_points(rows), closest);
                std::vector<Hit> as_hits(closest.size());
                for (size_t i = 0; i < closest.size(); ++i) {
                    as_hits[i] = Hit{0.0f, closest[i].u, closest[i].v, closest[i].prim};
                    const Vec3f q = closest[i].prim == kInvalidId ? Vec3f(std::nanf("")) : closest[i].point;
                    p[3 * i] = q.x, p[3 * i + 1] = q.y, p[3 * i + 2] = q.z;
                }
                fill_hits(as_hits, out);
            });
        }
        pyb::dict d;
        d["points"] = points;
        d["geometry_ids"] = geometry_ids;
        d["primitive_ids"] = primitive_ids;
        d["primitive_uvs"] = uvs;
        d["primitive_normals"] = normals;
        return d;
    }

    pyb::array compute_distance(const pyb::handle& query_points, int nthreads) {
        return distances(query_points, nthreads, std::nullopt, 1);
    }

    pyb::array compute_signed_distance(const pyb::handle& query_points, int nthreads, int nsamples,
                                       const std::string& sign) {
        return distances(query_points, nthreads, parse_sign(sign), nsamples);
    }

    pyb::array compute_occupancy(const pyb::handle& query_points, int nthreads, int nsamples, const std::string& sign) {
        const Sign s = parse_sign(sign);
        check_samples(nsamples);
        const FloatRows rows = float_rows(query_points, 3, "query_points");
        auto out = output<float>(rows.leading);
        float* o = out.mutable_data();
        const Reading r = read(nthreads, true);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            std::vector<uint8_t> inside(rows.rows);
            r.run([&] { inside_of(as_points(rows), s, nsamples, inside); });
            std::copy(inside.begin(), inside.end(), o);
        }
        return out;
    }

    [[nodiscard]] std::string device() const { return to_string(options_.device); }
    [[nodiscard]] size_t geometry_count() const { return scene_.meshes.size(); }

private:
    // A query's thread count; run() runs its work on that many threads.
    struct Reading {
        int threads = 0;
        template <class F>
        void run(F&& f) const {
            parallel::with_threads(threads, [&] {
                f();
                return 0;
            });
        }
    };
    // Checks before the GIL is released; the mesh queries are made from now on.
    Reading read(int nthreads, bool mesh_queries) {
        if (scene_.meshes.empty()) throw pyb::value_error("the scene has no geometry: add_triangles first");
        if (mesh_queries) need_queries_.store(true);
        return Reading{thread_count(nthreads) > 0 ? nthreads : nthreads_};
    }

    // Held shared, with the world (and the mesh queries once any query needed
    // them) made; made under the exclusive lock when missing.
    std::shared_lock<std::shared_mutex> ready() {
        for (;;) {
            std::shared_lock<std::shared_mutex> shared(mutex_);
            if (world_ && (!need_queries_.load() || queries_)) return shared;
            shared.unlock();
            std::unique_lock<std::shared_mutex> exclusive(mutex_);
            if (!world_) {
                world_ = make_world(scene_, options_);
                world_->commit();
            }
            if (need_queries_.load() && !queries_) {
                BuildOptions build = options_.build;
                build.device = Device{};
                queries_ = MeshQueries::build(world_->geometry().triangles, build);
            }
        }
    }

    // Per-hit outputs from flat hits, held shared by the caller.
    void fill_hits(std::span<const Hit> hits, const HitOutputs& out) const { fill_hit_outputs(*world_, hits, out); }

    static void check_samples(int nsamples) {
        if (nsamples < 1 || nsamples % 2 == 0 || nsamples > 31)
            throw pyb::value_error("nsamples: expected an odd count from 1 to 31 (the parity sign's majority vote), "
                                   "got " + std::to_string(nsamples));
    }

    // Whether each point is inside: the generalised winding number >= 1/2, or
    // Open3D's rule, an odd count of crossings along most of `nsamples` rays.
    void inside_of(std::span<const Vec3f> points, Sign sign, int nsamples, std::span<uint8_t> inside) {
        if (sign == Sign::Winding) {
            std::vector<float> w(points.size());
            queries_->winding_numbers(points, w);
            for (size_t i = 0; i < points.size(); ++i) inside[i] = w[i] >= 0.5f ? 1 : 0;
            return;
        }
        std::vector<uint8_t> votes(points.size(), 0);
        std::vector<Ray> rays(points.size());
        std::vector<uint32_t> counts(points.size());
        for (int k = 0; k < nsamples; ++k) {
            const Vec3f dir = parity_direction(k);
            for (size_t i = 0; i < points.size(); ++i) rays[i] = Ray{points[i], 0.0f, dir, kInfinity};
            queries_->count_intersections(rays, counts);
            for (size_t i = 0; i < points.size(); ++i) votes[i] += counts[i] % 2;
        }
        for (size_t i = 0; i < points.size(); ++i) inside[i] = 2 * votes[i] > nsamples ? 1 : 0;
    }

    pyb::array distances(const pyb::handle& query_points, int nthreads, std::optional<Sign> sign, int nsamples) {
        if (sign) check_samples(nsamples);
        const FloatRows rows = float_rows(query_points, 3, "query_points");
        auto out = output<float>(rows.leading);
        float* d = out.mutable_data();
        const Reading r = read(nthreads, true);
        {
            pyb::gil_scoped_release release;
            const std::shared_lock<std::shared_mutex> lock = ready();
            const std::span<const Vec3f> points = as_points(rows);
            std::vector<ClosestPoint> closest(points.size());
            std::vector<uint8_t> inside(sign ? points.size() : 0);
            r.run([&] {
                queries_->closest_points(points, closest);
                if (sign) inside_of(points, *sign, nsamples, inside);
            });
            for (size_t i = 0; i < points.size(); ++i) {
                const float distance = closest[i].prim == kInvalidId ? kInf : length(closest[i].point - points[i]);
                d[i] = sign && inside[i] ? -distance : distance;
            }
        }
        return out;
    }

    int nthreads_ = 0;
    WorldOptions options_;
    Scene scene_;  // the geometry added so far (the world's own copy is made from it)
    std::shared_ptr<World> world_;
    std::unique_ptr<MeshQueries> queries_;
    std::atomic<bool> need_queries_{false};
    std::shared_mutex mutex_;
};

}  // namespace

void bind_raycasting_scene(pyb::module_& m) {
    pyb::class_<RaycastingScene>(
        m, "RaycastingScene",
        "Ray queries over triangle meshes with Open3D 0.18's RaycastingScene interface (method and argument "
        "names, shapes, dtypes and dictionary keys; numpy arrays where Open3D returns tensors). cast_rays and "
        "test_occlusions run on `device` (cpu, cuda, cuda:N); the other queries run on the CPU.")
        .def(pyb::init<int, const std::string&, const std::string&, const std::string&>(), pyb::arg("nthreads") = 0,
             pyb::kw_only(), pyb::arg("device") = "cpu", pyb::arg("builder") = "binned", pyb::arg("layout") = "bvh8")
        .def_property_readonly_static("INVALID_ID", [](const pyb::object&) { return kInvalidId; },
                                      "0xFFFFFFFF: the id of nothing (a miss)")
        .def_property_readonly("device", &RaycastingScene::device, "where cast_rays and test_occlusions run")
        .def_property_readonly("geometry_count", &RaycastingScene::geometry_count, "meshes added")
        .def("add_triangles", &RaycastingScene::add_triangles, pyb::arg("vertex_positions"),
             pyb::arg("triangle_indices"),
             "Adds a mesh: vertex_positions (n, 3) float32, triangle_indices (m, 3) uint32. Returns its geometry id.")
        .def("refit", &RaycastingScene::refit, pyb::arg("geometry_id"), pyb::arg("vertex_positions"),
             "New vertex positions for a geometry (same count): the structure is refitted, not rebuilt.")
        .def("cast_rays", &RaycastingScene::cast_rays, pyb::arg("rays"), pyb::arg("nthreads") = 0,
             "Closest hits of (..., 6) rays [ox, oy, oz, dx, dy, dz]: t_hit (inf on a miss), geometry_ids, "
             "primitive_ids (INVALID_ID on a miss), primitive_uvs (..., 2), primitive_normals (..., 3).")
        .def(
            "cast_rays_on_device",
            [](RaycastingScene& s, const pyb::handle& rays, const pyb::handle& hits, const std::optional<intptr_t>& stream) {
                s.trace_on_device(rays, &hits, nullptr, stream);
            },
            pyb::arg("rays"), pyb::arg("hits"), pyb::kw_only(), pyb::arg("stream") = pyb::none(),
            "Beyond Open3D: closest hits of rays in CUDA memory written into CUDA memory, nothing through the "
            "host (a scene made with device='cuda'; objects with __cuda_array_interface__ or __dlpack__): rays "
            "(n, 8) float32 [ox, oy, oz, tmin, dx, dy, dz, tmax], hits (n, 4) 4-byte [t, u, v, prim] with prim "
            "the world's flat triangle index as uint32 bits (0xFFFFFFFF on a miss); stream a cudaStream_t as int.")
        .def(
            "test_occlusions_on_device",
            [](RaycastingScene& s, const pyb::handle& rays, const pyb::handle& occluded,
               const std::optional<intptr_t>& stream) { s.trace_on_device(rays, nullptr, &occluded, stream); },
            pyb::arg("rays"), pyb::arg("occluded"), pyb::kw_only(), pyb::arg("stream") = pyb::none(),
            "Any hits of rays in CUDA memory (as cast_rays_on_device) into occluded (n,) uint8 or bool in CUDA memory.")
        .def("test_occlusions", &RaycastingScene::test_occlusions, pyb::arg("rays"), pyb::arg("tnear") = 0.0f,
             pyb::arg("tfar") = kInf, pyb::arg("nthreads") = 0,
             "Whether each ray hits anything with t in [tnear, tfar] (bool).")
        .def("count_intersections", &RaycastingScene::count_intersections, pyb::arg("rays"), pyb::arg("nthreads") = 0,
             "Hits along each whole ray (int32); a ray through a shared edge or vertex crosses once.")
        .def("list_intersections", &RaycastingScene::list_intersections, pyb::arg("rays"), pyb::arg("nthreads") = 0,
             "Every hit along each ray, sorted by t: ray_splits (rays + 1 prefix sums), ray_ids, t_hit, "
             "geometry_ids, primitive_ids, primitive_uvs.")
        .def("compute_closest_points", &RaycastingScene::compute_closest_points, pyb::arg("query_points"),
             pyb::arg("nthreads") = 0,
             "The closest surface point of (..., 3) points: points, geometry_ids, primitive_ids, primitive_uvs, "
             "primitive_normals.")
        .def("compute_distance", &RaycastingScene::compute_distance, pyb::arg("query_points"), pyb::arg("nthreads") = 0,
             "Distance from each point to the surface (float32).")
        .def("compute_signed_distance", &RaycastingScene::compute_signed_distance, pyb::arg("query_points"),
             pyb::arg("nthreads") = 0, pyb::arg("nsamples") = 1, pyb::arg("sign") = "winding",
             "Distance, negative inside. sign='winding': inside where the generalised winding number is at least "
             "1/2 (right on open meshes and meshes with holes); sign='parity': Open3D's odd crossing count along "
             "nsamples rays (majority).")
        .def("compute_occupancy", &RaycastingScene::compute_occupancy, pyb::arg("query_points"),
             pyb::arg("nthreads") = 0, pyb::arg("nsamples") = 1, pyb::arg("sign") = "winding",
             "1.0 inside, 0.0 outside (float32), by the same sign rules as compute_signed_distance.");
}

}  // namespace rf::py
