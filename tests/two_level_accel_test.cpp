// The two-level structure (accel/update/two_level_accel.cpp, traversal
// trace/two_level_traversal.h): hits and occlusion against brute force over
// the flat SceneGeometry while instances move rigidly (rotation, non-uniform
// and mirroring scale), a mesh deforms, an instance is hidden; watertight
// rays through shared vertices; the RF_HD traversal over hand-made plain
// views (what a CUDA kernel calls); errors. A disabled test measures update
// and trace rates against a flat BVH8 rebuild on builtin:instances.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/update/bvh_updater.h"
#include "accel_test_scenes.h"
#include "core/parallel.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"
#include "trace/two_level_traversal.h"

namespace rf {
namespace {

using test::to_mesh;

// An open n x n grid of quads in the z = 0 plane over [-1, 1]^2.
Mesh make_patch(int n) {
    Mesh mesh;
    mesh.name = "patch";
    for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i)
            mesh.positions.emplace_back(-1.0f + 2.0f * float(i) / float(n), -1.0f + 2.0f * float(j) / float(n), 0.0f);
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) {
            const uint32_t a = uint32_t(j * (n + 1) + i), b = a + 1, c = a + uint32_t(n + 1), d = c + 1;
            mesh.indices.insert(mesh.indices.end(), {a, b, d, a, d, c});
        }
    }
    return mesh;
}

// Translation, rotation about a random axis, non-uniform scale (mirrored on
// one axis now and then).
Affine3f random_transform(std::mt19937& rng, float spread) {
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    const Vec3f offset = test::random_in_box(rng, Box3f{Vec3f(-spread), Vec3f(spread)});
    const Affine3f rotation = Affine3f::rotation(test::random_direction(rng), unit(rng) * 6.2831853f);
    Vec3f scale(0.3f + 1.7f * unit(rng), 0.3f + 1.7f * unit(rng), 0.3f + 1.7f * unit(rng));
    if (unit(rng) < 0.2f) scale.y = -scale.y;
    return Affine3f::translation(offset) * rotation * Affine3f::scale(scale);
}

// Meshes 0: icosphere (320 triangles), 1: cube (108), 2: patch (72).
Scene make_scene(int instances, uint32_t seed, float spread) {
    Scene scene;
    scene.meshes.push_back(to_mesh(test::make_icosphere(2), "sphere"));
    scene.meshes.push_back(to_mesh(test::make_tessellated_cube(3), "cube"));
    scene.meshes.push_back(make_patch(6));
    std::mt19937 rng(seed);
    for (int i = 0; i < instances; ++i) scene.instances.push_back({uint32_t(i % 3), random_transform(rng, spread)});
    scene.finalize();
    return scene;
}

// Random rays and rays aimed inside triangles (not at their edges: a
// transformed ray may pick the other triangle of an edge), with zero
// direction components and [tmin, tmax] limits now and then.
std::vector<Ray> make_rays(const SceneGeometry& g, size_t count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::uniform_int_distribution<size_t> pick(0, g.triangles.size() - 1);
    const Vec3f margin = g.bounds.extent() * 0.25f + Vec3f(1e-3f);
    const Box3f around{g.bounds.lo - margin, g.bounds.hi + margin};
    std::vector<Ray> rays;
    for (size_t i = 0; i < count; ++i) {
        Ray ray;
        ray.org = test::random_in_box(rng, around);
        if (i % 3 == 0) {
            ray.dir = test::random_direction(rng);
        } else {
            const Triangle& tri = g.triangles[pick(rng)];
            const float b1 = 0.05f + 0.45f * unit(rng), b2 = 0.05f + 0.45f * unit(rng);
            ray.dir = tri.v0 * (1.0f - b1 - b2) + tri.v1 * b1 + tri.v2 * b2 - ray.org;
            if (length_squared(ray.dir) == 0.0f) ray.dir = Vec3f(0, 0, 1);
        }
        if (i % 11 == 0) {
            ray.dir[int(i % 3)] = 0.0f;
            if (length_squared(ray.dir) == 0.0f) ray.dir = Vec3f(1, 0, 0);
        }
        if (i % 7 == 0) {
            ray.tmin = 0.3f * unit(rng);
            ray.tmax = 0.5f + unit(rng);
        }
        rays.push_back(ray);
    }
    return rays;
}

bool near_edge(const Hit& h) { return std::min({h.u, h.v, 1.0f - h.u - h.v}) < 1e-4f; }
bool near_limit(const Hit& h, const Ray& r) {
    return std::fabs(h.t - r.tmax) <= 1e-4f * std::fabs(r.tmax) || std::fabs(h.t - r.tmin) <= 1e-4f;
}
bool same_t(float a, float b) { return std::fabs(a - b) <= 1e-4f * std::max(std::fabs(b), 1e-3f); }

// Closest hits and occlusion equal brute force's. A transformed ray may
// decide a ray through an edge or vertex (or exactly at tmin/tmax)
// differently; such rays are counted and must stay rare.
void expect_matches_brute_force(const Accel& accel, const SceneGeometry& g, const std::vector<Ray>& rays,
                                const std::string& what) {
    const BruteForceAccel brute(g);
    std::vector<Hit> got(rays.size()), want(rays.size());
    std::vector<uint8_t> got_occ(rays.size()), want_occ(rays.size());
    accel.intersect(rays, got);
    brute.intersect(rays, want);
    accel.occluded(rays, got_occ);
    brute.occluded(rays, want_occ);
    size_t tolerated = 0, hits = 0, failures = 0;
    for (size_t i = 0; i < rays.size() && failures < 5; ++i) {
        const Hit& a = got[i];
        const Hit& b = want[i];
        const bool ambiguous = (a.found() && (near_edge(a) || near_limit(a, rays[i]))) ||
                               (b.found() && (near_edge(b) || near_limit(b, rays[i])));
        bool ok = a.found() == b.found();
        if (ok && b.found()) {
            ++hits;
            if (a.prim == b.prim) {
                // Barycentrics loosely: grazing rays amplify the rounding of either transform.
                ok = same_t(a.t, b.t) && std::fabs(a.u - b.u) < 1e-2f && std::fabs(a.v - b.v) < 1e-2f;
            } else {
                ok = false;
                if (same_t(a.t, b.t)) {  // a tie: two surfaces meet where the ray crosses them
                    ++tolerated;
                    ok = true;
                }
            }
        }
        if (ok && got_occ[i] != want_occ[i]) ok = false;
        if (!ok && ambiguous) {
            ++tolerated;
            ok = true;
        }
        if (!ok) {
            ++failures;
            ADD_FAILURE() << what << ": ray " << i << " got prim " << a.prim << " t " << a.t << " occluded "
                          << int(got_occ[i]) << ", brute force prim " << b.prim << " t " << b.t << " occluded "
                          << int(want_occ[i]);
        }
    }
    EXPECT_LE(tolerated, rays.size() / 100) << what;
    EXPECT_GT(hits, rays.size() / 3) << what << ": too few hits to test anything";
}

BuildOptions options_for(Layout layout) {
    BuildOptions o;
    o.layout = layout;
    return o;
}

class TwoLevelAccelLayouts : public ::testing::TestWithParam<Layout> {};

TEST_P(TwoLevelAccelLayouts, RigidInstancesOverFramesMatchBruteForce) {
    Scene scene = make_scene(30, 7, 5.0f);
    SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, options_for(GetParam()));
    EXPECT_EQ(accel->method(), UpdateMethod::TwoLevel);
    std::mt19937 rng(11);
    for (int frame = 0; frame < 3; ++frame) {
        if (frame > 0) {
            GeometryChange change;
            for (uint32_t i = 0; i < scene.instances.size(); ++i) {
                if (i % 2 == uint32_t(frame % 2)) continue;  // half the instances stay
                scene.instances[i].transform = random_transform(rng, 5.0f);
                change.instances.push_back(i);
            }
            g.update(scene, change);
            const UpdateStats stats = accel->update(change);
            EXPECT_EQ(stats.meshes_updated, 0u);
            EXPECT_GT(stats.sah_cost, 1.0);
        }
        expect_matches_brute_force(*accel, g, make_rays(g, 1000, 100 + frame), "frame " + std::to_string(frame));
    }
}

TEST_P(TwoLevelAccelLayouts, DeformingMeshIsRefitted) {
    Scene scene = make_scene(9, 3, 3.0f);  // instances 2, 5, 8 are the patch
    SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, options_for(GetParam()));
    const std::vector<Vec3f> rest = scene.meshes[2].positions;
    for (int frame = 1; frame <= 3; ++frame) {
        // A wave growing each frame, well outside the rest pose's box.
        for (size_t v = 0; v < rest.size(); ++v) {
            const Vec3f p = rest[v];
            scene.meshes[2].positions[v] =
                Vec3f(p.x * (1.0f + 0.3f * float(frame)), p.y, float(frame) * std::sin(3.0f * p.x + float(frame)) * p.y);
        }
        GeometryChange change;
        change.meshes = {2};
        change.instances = {2, 5, 8};
        g.update(scene, change);
        const UpdateStats stats = accel->update(change);
        EXPECT_EQ(stats.meshes_updated, 1u);
        expect_matches_brute_force(*accel, g, make_rays(g, 1000, 200 + frame), "frame " + std::to_string(frame));
    }
}

TEST_P(TwoLevelAccelLayouts, HiddenInstanceIsSkipped) {
    Scene scene = make_scene(12, 5, 4.0f);
    SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, options_for(GetParam()));
    const Vec3f centre = scene.instances[3].transform.transform_point(Vec3f(0.0f));
    // Rays from all around at the hidden instance's centre.
    std::vector<Ray> rays = make_rays(g, 600, 300);
    std::mt19937 rng(5);
    for (int i = 0; i < 200; ++i) {
        const Vec3f dir = test::random_direction(rng);
        rays.push_back(Ray{centre - dir * 20.0f, 0.0f, dir, kInfinity});
    }
    const size_t before = accel->stats().leaf_count;
    scene.instances[3].visible = false;
    GeometryChange change;
    change.instances = {3};
    g.update(scene, change);
    accel->update(change);
    EXPECT_EQ(accel->stats().leaf_count, before - 1);  // one top-level leaf fewer
    expect_matches_brute_force(*accel, g, rays, "hidden");
    scene.instances[3].visible = true;
    g.update(scene, change);
    accel->update(change);
    expect_matches_brute_force(*accel, g, rays, "shown again");
}

INSTANTIATE_TEST_SUITE_P(TwoLevel, TwoLevelAccelLayouts, ::testing::Values(Layout::Bvh2, Layout::Bvh4, Layout::Bvh8),
                         [](const auto& info) { return to_string(info.param); });

// Rays along the radius through every vertex of closed spheres under
// rotation and non-uniform scale: the watertight test in object space lets
// none slip through the shared vertices.
TEST(TwoLevelAccel, RaysThroughSharedVerticesHit) {
    Scene scene;
    scene.meshes.push_back(to_mesh(test::make_icosphere(2), "sphere"));
    std::mt19937 rng(9);
    for (int i = 0; i < 3; ++i) scene.instances.push_back({0, random_transform(rng, 10.0f)});
    scene.finalize();
    const SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, BuildOptions{});
    int missed = 0, rays = 0;
    for (const Instance& inst : scene.instances) {
        const Vec3f centre = inst.transform.transform_point(Vec3f(0.0f));
        for (const Vec3f& p : scene.meshes[0].positions) {
            const Vec3f vertex = inst.transform.transform_point(p);
            const Vec3f dir = centre - vertex;
            ++rays;
            const Hit hit = accel->intersect(Ray{vertex - dir * 3.0f, 0.0f, dir, kInfinity});
            if (!hit.found() || !same_t(hit.t, 3.0f)) ++missed;  // entered at the vertex, not further on
        }
    }
    EXPECT_EQ(missed, 0) << "of " << rays;
}

TEST(TwoLevelAccel, StatsNameAndErrors) {
    Scene scene = make_scene(6, 1, 3.0f);
    scene.meshes.push_back(make_patch(2));
    SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, BuildOptions{});
    const AccelStats s = accel->stats();
    EXPECT_EQ(s.name, "two-level/binned/bvh8");
    EXPECT_GT(s.node_count, 3u);
    EXPECT_GT(s.bytes, 0u);
    EXPECT_GE(accel->initial_build_ms(), 0.0);
    GeometryChange bad;
    bad.meshes = {4};
    EXPECT_THROW(accel->update(bad), Error);
    GeometryChange unused;  // mesh 3: no instance uses it, nothing to update
    unused.meshes = {3};
    EXPECT_EQ(accel->update(unused).meshes_updated, 0u);
    scene.meshes[1].indices.resize(scene.meshes[1].indices.size() - 3);
    bad.meshes = {1};
    EXPECT_THROW(accel->update(bad), Error);
    BuildOptions cuda;
    cuda.device = Device{Device::Kind::Cuda, 0};
    EXPECT_THROW(make_two_level_accel(scene, g, cuda), Error);
    BuildOptions grid;
    grid.structure = Structure::Grid;
    EXPECT_THROW(make_two_level_accel(scene, g, grid), Error);
}

TEST(TwoLevelAccel, EveryInstanceHiddenMissesEverything) {
    Scene scene = make_scene(4, 2, 3.0f);
    SceneGeometry g = SceneGeometry::build(scene);
    auto accel = make_two_level_accel(scene, g, BuildOptions{});
    GeometryChange change;
    for (uint32_t i = 0; i < scene.instances.size(); ++i) {
        scene.instances[i].visible = false;
        change.instances.push_back(i);
    }
    g.update(scene, change);
    accel->update(change);
    for (const Ray& ray : make_rays(g, 100, 1)) {
        EXPECT_FALSE(accel->intersect(ray).found());
        EXPECT_FALSE(accel->occluded(ray));
    }
}

// The RF_HD traversal over plain views built by hand, as a kernel gets
// them: binary bottom levels, a top level with several instances per leaf,
// rays in shuffled order (each ray is independent of the schedule).
TEST(TwoLevelDeviceLogic, TracerOverPlainViewsMatchesBruteForce) {
    Scene scene = make_scene(24, 21, 5.0f);
    scene.instances[4].visible = false;
    const SceneGeometry g = SceneGeometry::build(scene);
    BuildOptions options;
    std::vector<std::vector<Triangle>> object(scene.meshes.size());
    std::vector<Bvh> blas(scene.meshes.size());
    std::vector<BvhView> views(scene.meshes.size());
    for (size_t m = 0; m < scene.meshes.size(); ++m) {
        const Mesh& mesh = scene.meshes[m];
        for (size_t t = 0; t < mesh.triangle_count(); ++t)
            object[m].push_back({mesh.positions[mesh.indices[3 * t]], mesh.positions[mesh.indices[3 * t + 1]],
                                 mesh.positions[mesh.indices[3 * t + 2]]});
        blas[m] = build_bvh_on_cpu(object[m], options);
        views[m] = BvhView{blas[m].nodes.data(), blas[m].prim_indices.data(), object[m].data(),
                           uint32_t(blas[m].nodes.size())};
    }
    std::vector<TwoLevelInstance> instances;
    std::vector<Triangle> boxes;
    for (uint32_t i = 0; i < scene.instances.size(); ++i) {
        const Instance& inst = scene.instances[i];
        if (!inst.visible) continue;
        instances.push_back({inst.transform.inverse(), inst.mesh, g.instance_first_triangle[i]});
        Box3f box = inst.transform.transform_box(blas[inst.mesh].nodes[0].bounds);
        box = Box3f{box.lo - Vec3f(1e-4f), box.hi + Vec3f(1e-4f)};
        boxes.push_back({box.lo, box.hi, box.center()});
    }
    options.max_leaf_size = 4;
    const Bvh top = build_bvh_on_cpu(boxes, options);
    ASSERT_LT(top.leaf_count(), instances.size());  // some leaves hold several instances
    const TwoLevelBvh2Tracer tracer{TwoLevelView<BvhView>{top.nodes.data(), top.prim_indices.data(),
                                                          uint32_t(top.nodes.size()), instances.data(), views.data()}};

    std::vector<Ray> rays = make_rays(g, 1000, 77);
    std::shuffle(rays.begin(), rays.end(), std::mt19937(3));
    struct TracerAccel final : Accel {
        explicit TracerAccel(const TwoLevelBvh2Tracer& t) : tracer(t) {}
        [[nodiscard]] Hit intersect(const Ray& ray) const override { return tracer.intersect(ray); }
        [[nodiscard]] bool occluded(const Ray& ray) const override { return tracer.occluded(ray); }
        [[nodiscard]] AccelStats stats() const override { return {}; }
        using Accel::intersect;
        using Accel::occluded;
        TwoLevelBvh2Tracer tracer;
    };
    expect_matches_brute_force(TracerAccel(tracer), g, rays, "plain views");

    // The instrumented traversal (the device's count and wavefront kernels
    // take it) answers the same, and counts both levels' work.
    RayCounters counts;
    for (const Ray& ray : rays) {
        const Hit want = tracer.intersect(ray);
        const Hit closest = tracer.counted(ray, false, counts);
        EXPECT_EQ(closest.prim, want.prim);
        EXPECT_EQ(closest.t, want.t);
        EXPECT_EQ(tracer.counted(ray, true, counts).found(), tracer.occluded(ray));
    }
    RayCounters top_only;  // a ray that misses everything tests the top root alone
    EXPECT_FALSE(tracer.counted(Ray{g.bounds.hi + Vec3f(10.0f), 0.0f, Vec3f(1, 0, 0), kInfinity}, false, top_only)
                     .found());
    EXPECT_EQ(top_only.steps, 1u);
    EXPECT_EQ(top_only.prim_tests, 0u);
    EXPECT_GT(counts.steps, 2 * rays.size());  // the top root and a bottom root at least, per query
    EXPECT_GT(counts.prim_tests, 0u);
}

// ---------------------------------------------------------------------------
// Measurement (run with --gtest_also_run_disabled_tests): builtin:instances
// with every instance but the ground moving rigidly; per frame the
// two-level update against a flat binned BVH8 rebuild, and both traced on
// the same primary and diffuse rays.

double ms_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

std::vector<Ray> camera_rays(const Scene& scene, int width, int height) {
    const Camera cam = scene.camera_or_default();
    const Vec3f forward = normalize(cam.target - cam.eye);
    const Vec3f right = normalize(cross(forward, cam.up));
    const Vec3f up = cross(right, forward);
    const float h = std::tan(cam.vfov_degrees * 0.5f * 3.14159265f / 180.0f), w = h * float(width) / float(height);
    std::vector<Ray> rays;
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const float sx = (2.0f * (float(x) + 0.5f) / float(width) - 1.0f) * w;
            const float sy = (1.0f - 2.0f * (float(y) + 0.5f) / float(height)) * h;
            rays.push_back(Ray{cam.eye, 0.0f, normalize(forward + right * sx + up * sy), kInfinity});
        }
    return rays;
}

// Cosine-distributed bounces from the primary hits (misses bounce nowhere).
std::vector<Ray> diffuse_rays(const SceneGeometry& g, const std::vector<Ray>& primary, const std::vector<Hit>& hits) {
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<Ray> rays;
    for (size_t i = 0; i < primary.size(); ++i) {
        if (!hits[i].found()) continue;
        Vec3f n = normalize(g.triangles[hits[i].prim].geometric_normal());
        if (dot(n, primary[i].dir) > 0.0f) n = -n;
        const Vec3f a = std::fabs(n.x) > 0.9f ? Vec3f(0, 1, 0) : Vec3f(1, 0, 0);
        const Vec3f t = normalize(cross(n, a)), b = cross(n, t);
        const float r = std::sqrt(unit(rng)), phi = 6.2831853f * unit(rng);
        const Vec3f dir = t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * std::sqrt(1.0f - r * r);
        const Vec3f p = primary[i].org + primary[i].dir * hits[i].t;
        rays.push_back(Ray{p + n * 1e-4f, 0.0f, dir, kInfinity});
    }
    return rays;
}

double mrays_per_s(const Accel& accel, const std::vector<Ray>& rays) {
    std::vector<Hit> hits(rays.size());
    accel.intersect(rays, hits);  // warm-up
    double best = 1e30;
    for (int run = 0; run < 3; ++run) {
        const auto start = std::chrono::steady_clock::now();
        accel.intersect(rays, hits);
        best = std::min(best, ms_since(start));
    }
    return double(rays.size()) / (best * 1e3);
}

TEST(TwoLevelAccel, DISABLED_MeasureInstancesAgainstFlatRebuild) {
    Scene scene = load_scene("builtin:instances");
    SceneGeometry g = SceneGeometry::build(scene);
    const BuildOptions options;  // binned, BVH8
    const std::vector<Affine3f> rest = [&] {
        std::vector<Affine3f> r;
        for (const Instance& i : scene.instances) r.push_back(i.transform);
        return r;
    }();
    auto two_level = make_two_level_accel(scene, g, options);
    std::printf("builtin:instances: %zu instances, %zu triangles; two-level initial build %.2f ms\n",
                scene.instances.size(), g.size(), two_level->initial_build_ms());
    std::printf("frame  update_ms  rebuild_ms  primary Mrays/s (2L / flat)  diffuse Mrays/s (2L / flat)  sah (2L / flat)\n");
    double sums[6] = {};
    const int frames = 5;
    for (int frame = 1; frame <= frames; ++frame) {
        GeometryChange change;
        for (uint32_t i = 1; i < scene.instances.size(); ++i) {  // instance 0 is the ground
            const float phase = 0.37f * float(i) + 0.4f * float(frame);
            scene.instances[i].transform =
                Affine3f::translation(Vec3f(0.6f * std::sin(phase), 0.3f + 0.3f * std::sin(1.7f * phase),
                                            0.6f * std::cos(phase))) * rest[i];
            change.instances.push_back(i);
        }
        g.update(scene, change);
        const UpdateStats stats = two_level->update(change);
        const auto start = std::chrono::steady_clock::now();
        auto flat = build_accel(g, options);
        const double rebuild_ms = ms_since(start);
        const std::vector<Ray> primary = camera_rays(scene, 1024, 512);
        std::vector<Hit> hits(primary.size());
        flat->intersect(primary, hits);
        const std::vector<Ray> diffuse = diffuse_rays(g, primary, hits);
        const double v[6] = {stats.update_ms, rebuild_ms, mrays_per_s(*two_level, primary), mrays_per_s(*flat, primary),
                             mrays_per_s(*two_level, diffuse), mrays_per_s(*flat, diffuse)};
        std::printf("%5d  %9.2f  %10.2f  %12.2f / %-12.2f  %12.2f / %-12.2f  %.1f / %.1f\n", frame, v[0], v[1], v[2],
                    v[3], v[4], v[5], stats.sah_cost, flat->stats().sah_cost);
        for (int k = 0; k < 6; ++k) sums[k] += v[k];
        expect_matches_brute_force(*two_level, g, make_rays(g, 200, frame), "measured frame");
    }
    std::printf("mean   %9.2f  %10.2f  %12.2f / %-12.2f  %12.2f / %-12.2f\n", sums[0] / frames, sums[1] / frames,
                sums[2] / frames, sums[3] / frames, sums[4] / frames, sums[5] / frames);
}

}  // namespace
}  // namespace rf
