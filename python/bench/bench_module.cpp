// rayforge._rayforge_bench: the reference rows of `python3 -m rayforge.bench`
// (python/rayforge/bench.py), in the build tree only (not installed).
//   CppScene: the batches a C++ program would run through the public API on
//     rays and points it already holds in the engine's layout (std::vector of
//     Ray / Vec3f, made before the clock starts), producing the outputs the
//     Python calls return: World::intersect plus the five per-hit arrays of
//     cast_rays, World::occluded, MeshQueries::closest_points, and
//     closest_points plus winding_numbers for the signed distance.
//   EmbreeScene: Embree (bench/harness/embree_peer.h, the CLI bench's peer),
//     rtcIntersect1 / rtcOccluded1 per ray, parallel over rays.
// Every call returns (seconds, result) so bench.py can check that the rows
// agree before it prints them.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <chrono>
#include <cmath>
#include <limits>

#include "core/parallel.h"
#include "embree_peer.h"
#include "rayforge/accel/mesh_queries.h"
#include "rayforge/world.h"

namespace pyb = pybind11;

namespace rf::bench_py {
namespace {

using Clock = std::chrono::steady_clock;
using FloatArray = pyb::array_t<float, pyb::array::c_style | pyb::array::forcecast>;
using IndexArray = pyb::array_t<uint32_t, pyb::array::c_style | pyb::array::forcecast>;
constexpr float kInf = std::numeric_limits<float>::infinity();

double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

Scene scene_of(const FloatArray& vertices, const IndexArray& triangles) {
    if (vertices.ndim() != 2 || vertices.shape(1) != 3 || triangles.ndim() != 2 || triangles.shape(1) != 3)
        throw pyb::value_error("expected vertices (n, 3) and triangles (m, 3)");
    Scene scene;
    scene.materials.push_back(Material{});
    Mesh mesh;
    const auto* v = reinterpret_cast<const Vec3f*>(vertices.data());
    mesh.positions.assign(v, v + vertices.shape(0));
    mesh.indices.assign(triangles.data(), triangles.data() + triangles.size());
    mesh.material_ids.assign(mesh.triangle_count(), 0);
    mesh.validate();
    scene.meshes.push_back(std::move(mesh));
    scene.instances.push_back({0, Affine3f::identity()});
    return scene;
}

std::vector<Ray> rays_of(const FloatArray& rays) {
    std::vector<Ray> out(size_t(rays.size()) / 6);
    const float* r = rays.data();
    for (size_t i = 0; i < out.size(); ++i, r += 6) out[i] = Ray{{r[0], r[1], r[2]}, 0.0f, {r[3], r[4], r[5]}, kInf};
    return out;
}

std::vector<Vec3f> points_of(const FloatArray& points) {
    const auto* p = reinterpret_cast<const Vec3f*>(points.data());
    return {p, p + points.size() / 3};
}

template <class T>
pyb::array_t<T> to_array(const std::vector<T>& values) {
    pyb::array_t<T> out(pyb::ssize_t(values.size()));
    std::copy(values.begin(), values.end(), out.mutable_data());
    return out;
}

// The World and MeshQueries a RaycastingScene makes with its defaults
// (binned SAH, BVH8, refit), driven from C++.
class CppScene {
public:
    CppScene(const FloatArray& vertices, const IndexArray& triangles, int threads) : threads_(threads) {
        WorldOptions options;
        options.build.threads = threads;
        options.update.method = UpdateMethod::Refit;
        Scene scene = scene_of(vertices, triangles);
        pyb::gil_scoped_release release;
        Clock::time_point start = Clock::now();
        world_ = make_world(std::move(scene), options);
        world_->commit();
        world_ms_ = 1e3 * seconds_since(start);
        start = Clock::now();
        queries_ = MeshQueries::build(world_->geometry().triangles, options.build);
        queries_ms_ = 1e3 * seconds_since(start);
    }

    pyb::tuple cast_rays(const FloatArray& rays) const {
        const std::vector<Ray> r = rays_of(rays);
        std::vector<float> t(r.size()), uvs(2 * r.size()), normals(3 * r.size());
        std::vector<uint32_t> geometry_ids(r.size()), primitive_ids(r.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            s = timed([&] {
                std::vector<Hit> hits(r.size());
                world_->intersect(r, hits);
                const SceneGeometry& g = world_->geometry();
                parallel::for_range(size_t(0), hits.size(), size_t(4096), [&](size_t lo, size_t hi) {
                    for (size_t i = lo; i < hi; ++i) {
                        const Hit& h = hits[i];
                        const bool found = h.found();
                        t[i] = found ? h.t : kInf;
                        geometry_ids[i] = found ? g.triangle_instance[h.prim] : kInvalidId;
                        primitive_ids[i] = found ? g.local_triangle[h.prim] : kInvalidId;
                        uvs[2 * i] = found ? h.u : 0.0f;
                        uvs[2 * i + 1] = found ? h.v : 0.0f;
                        const Vec3f n = found ? normalize(g.triangles[h.prim].geometric_normal()) : Vec3f(0.0f);
                        normals[3 * i] = n.x, normals[3 * i + 1] = n.y, normals[3 * i + 2] = n.z;
                    }
                });
            });
        }
        return pyb::make_tuple(s, to_array(t));
    }

    pyb::tuple test_occlusions(const FloatArray& rays) const {
        const std::vector<Ray> r = rays_of(rays);
        std::vector<uint8_t> blocked(r.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            s = timed([&] { world_->occluded(r, blocked); });
        }
        return pyb::make_tuple(s, to_array(blocked));
    }

    pyb::tuple closest_points(const FloatArray& points) const {
        const std::vector<Vec3f> p = points_of(points);
        std::vector<ClosestPoint> closest(p.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            s = timed([&] { queries_->closest_points(p, closest); });
        }
        std::vector<float> d(p.size());
        for (size_t i = 0; i < p.size(); ++i) d[i] = length(closest[i].point - p[i]);
        return pyb::make_tuple(s, to_array(d));
    }

    pyb::tuple signed_distance(const FloatArray& points) const {
        const std::vector<Vec3f> p = points_of(points);
        std::vector<float> d(p.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            s = timed([&] {
                std::vector<ClosestPoint> closest(p.size());
                std::vector<float> w(p.size());
                queries_->closest_points(p, closest);
                queries_->winding_numbers(p, w);
                for (size_t i = 0; i < p.size(); ++i) {
                    const float distance = length(closest[i].point - p[i]);
                    d[i] = w[i] >= 0.5f ? -distance : distance;
                }
            });
        }
        return pyb::make_tuple(s, to_array(d));
    }

    double world_ms() const { return world_ms_; }
    double queries_ms() const { return queries_ms_; }

private:
    template <class F>
    double timed(F&& f) const {
        return parallel::with_threads(threads_, [&] {
            const Clock::time_point start = Clock::now();
            f();
            return seconds_since(start);
        });
    }

    int threads_;
    std::unique_ptr<World> world_;
    std::unique_ptr<MeshQueries> queries_;
    double world_ms_ = 0.0, queries_ms_ = 0.0;
};

class EmbreeScene {
public:
    EmbreeScene(const FloatArray& vertices, const IndexArray& triangles, int threads, const std::string& quality) {
        const Scene scene = scene_of(vertices, triangles);
        geometry_ = SceneGeometry::build(scene);
        const bench::EmbreeQuality q = quality == "low"    ? bench::EmbreeQuality::Low
                                       : quality == "high" ? bench::EmbreeQuality::High
                                                           : bench::EmbreeQuality::Medium;
        pyb::gil_scoped_release release;
        peer_ = std::make_unique<bench::EmbreePeer>(geometry_, q, threads);
    }

    pyb::tuple intersect(const FloatArray& rays) const {
        const std::vector<Ray> r = rays_of(rays);
        std::vector<Hit> hits(r.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            const Clock::time_point start = Clock::now();
            peer_->intersect(r, hits);
            s = seconds_since(start);
        }
        std::vector<float> t(r.size());
        for (size_t i = 0; i < r.size(); ++i) t[i] = hits[i].found() ? hits[i].t : kInf;
        return pyb::make_tuple(s, to_array(t));
    }

    pyb::tuple occluded(const FloatArray& rays) const {
        const std::vector<Ray> r = rays_of(rays);
        std::vector<uint8_t> blocked(r.size());
        double s = 0.0;
        {
            pyb::gil_scoped_release release;
            const Clock::time_point start = Clock::now();
            peer_->occluded(r, blocked);
            s = seconds_since(start);
        }
        return pyb::make_tuple(s, to_array(blocked));
    }

    double build_ms() const { return peer_->build_ms(); }

private:
    SceneGeometry geometry_;
    std::unique_ptr<bench::EmbreePeer> peer_;
};

}  // namespace
}  // namespace rf::bench_py

PYBIND11_MODULE(_rayforge_bench, m) {
    using namespace rf::bench_py;
    m.doc() = "The C++ API and Embree rows of python3 -m rayforge.bench (build tree only).";
    m.def("embree_available", &rf::bench::embree_available);
    m.def("embree_version", &rf::bench::embree_version);
    pyb::class_<CppScene>(m, "CppScene")
        .def(pyb::init<const FloatArray&, const IndexArray&, int>(), pyb::arg("vertices"), pyb::arg("triangles"),
             pyb::arg("threads"))
        .def_property_readonly("world_ms", &CppScene::world_ms)
        .def_property_readonly("queries_ms", &CppScene::queries_ms)
        .def("cast_rays", &CppScene::cast_rays)
        .def("test_occlusions", &CppScene::test_occlusions)
        .def("closest_points", &CppScene::closest_points)
        .def("signed_distance", &CppScene::signed_distance);
    pyb::class_<EmbreeScene>(m, "EmbreeScene")
        .def(pyb::init<const FloatArray&, const IndexArray&, int, const std::string&>(), pyb::arg("vertices"),
             pyb::arg("triangles"), pyb::arg("threads"), pyb::arg("quality") = "medium")
        .def_property_readonly("build_ms", &EmbreeScene::build_ms)
        .def("intersect", &EmbreeScene::intersect)
        .def("occluded", &EmbreeScene::occluded);
}
