// Built-in scenes: every name loads and validates, the Cornell box and the
// sphere field have the geometry, materials, lights and cameras they promise,
// the procedural benchmark scenes (sphereflake, terrain, instances) are large,
// finite, lit and framed by their cameras, and generation is deterministic.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {
namespace {

void expect_vec(Vec3f actual, Vec3f expected, float eps = 1e-4f) {
    EXPECT_NEAR(actual.x, expected.x, eps);
    EXPECT_NEAR(actual.y, expected.y, eps);
    EXPECT_NEAR(actual.z, expected.z, eps);
}

TEST(BuiltinScenes, EveryNameLoadsThroughLoadScene) {
    const auto names = builtin_scene_names();
    ASSERT_GE(names.size(), 2u);
    for (const std::string& name : names) {
        Scene scene = load_scene("builtin:" + name);
        EXPECT_EQ(scene.source, "builtin:" + name);
        EXPECT_GT(scene.triangle_count(), 0u) << name;
        EXPECT_TRUE(scene.camera.has_value()) << name;
        for (const Mesh& mesh : scene.meshes) EXPECT_EQ(mesh.material_ids.size(), mesh.triangle_count()) << name;
    }
}

TEST(BuiltinScenes, UnknownNameListsTheKnownOnes) {
    try {
        load_scene("builtin:teapot");
        FAIL() << "no error";
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_NE(message.find("builtin:teapot"), std::string::npos) << message;
        EXPECT_NE(message.find("cornell"), std::string::npos) << message;
    }
}

TEST(BuiltinScenes, CornellBoxGeometryMaterialsAndLights) {
    Scene scene = load_scene("builtin:cornell");
    Box3f b = scene.bounds();
    expect_vec(b.lo, {-1, 0, -1});
    expect_vec(b.hi, {1, 2, 1});
    // 5 walls + light quad (12) + 2 boxes (24) + 2 spheres of 64 * (2 * 32 - 2).
    EXPECT_EQ(scene.triangle_count(), 12u + 24u + 2u * 64u * 62u);

    bool has_emitter = false, has_mirror = false, has_glass = false;
    for (const Material& m : scene.materials) {
        if (m.is_emissive()) {
            has_emitter = true;
            expect_vec(m.emitted_radiance(), {17, 12, 4});
        }
        has_mirror = has_mirror || (m.metallic == 1.0f && m.roughness == 0.0f);
        has_glass = has_glass || (m.transmission == 1.0f && m.ior == 1.5f);
    }
    EXPECT_TRUE(has_emitter);
    EXPECT_TRUE(has_mirror);
    EXPECT_TRUE(has_glass);

    ASSERT_FALSE(scene.lights.empty());
    EXPECT_EQ(scene.lights[0].type, LightType::Point);
    EXPECT_GT(scene.lights[0].position.y, 1.5f);
    EXPECT_LT(scene.lights[0].position.y, 2.0f);

    ASSERT_TRUE(scene.camera.has_value());
    expect_vec(scene.camera->eye, {0, 1, 3.9f});
    expect_vec(scene.camera->target, {0, 1, 0});
    EXPECT_FLOAT_EQ(scene.camera->vfov_degrees, 40.0f);
}

TEST(BuiltinScenes, CornellWallsFaceIntoTheRoom) {
    Scene scene = make_builtin_scene("cornell");
    const Vec3f center{0, 1, 0};
    const Mesh& room = scene.meshes[scene.instances[0].mesh];
    ASSERT_EQ(room.name, "room");
    for (size_t t = 0; t < room.triangle_count(); ++t) {
        Vec3f a = room.positions[room.indices[3 * t]], b = room.positions[room.indices[3 * t + 1]],
              c = room.positions[room.indices[3 * t + 2]];
        Vec3f n = cross(b - a, c - a);
        EXPECT_GT(dot(n, center - a), 0.0f) << "room triangle " << t;
    }
}

TEST(BuiltinScenes, SpheresIsLargeVariedAndDeterministic) {
    Scene a = load_scene("builtin:spheres");
    Scene b = load_scene("builtin:spheres");
    EXPECT_GT(a.triangle_count(), 100000u);
    EXPECT_GE(a.instances.size(), 100u);
    EXPECT_GE(a.materials.size(), 5u);
    bool metal = false, glass = false, emitter = false;
    for (const Material& m : a.materials) {
        metal = metal || m.metallic > 0.5f;
        glass = glass || m.transmission > 0.5f;
        emitter = emitter || m.is_emissive();
    }
    EXPECT_TRUE(metal && glass && emitter);
    // Every sphere rests on the ground plane y = 0.
    Box3f bounds = a.bounds();
    EXPECT_NEAR(bounds.lo.y, 0.0f, 1e-4f);

    ASSERT_EQ(a.instances.size(), b.instances.size());
    for (size_t i = 0; i < a.instances.size(); ++i) {
        EXPECT_EQ(a.instances[i].mesh, b.instances[i].mesh);
        EXPECT_EQ(std::memcmp(&a.instances[i].transform, &b.instances[i].transform, sizeof(Affine3f)), 0);
    }
}

TEST(BuiltinScenes, TinyScenes) {
    EXPECT_EQ(make_builtin_scene("triangle").triangle_count(), 1u);
    EXPECT_EQ(make_builtin_scene("plane").triangle_count(), 2u);
    EXPECT_EQ(make_builtin_scene("cube").triangle_count(), 12u);
    Box3f cube = make_builtin_scene("cube").bounds();
    expect_vec(cube.lo, {-0.5f, -0.5f, -0.5f});
    expect_vec(cube.hi, {0.5f, 0.5f, 0.5f});
}


// The procedural benchmark scenes, the meshes each one is about (the rest is
// ground or water; "" = all but the ground), and whether the image centre
// shows them (between the instances it may show the ground).
struct BenchmarkScene {
    const char* name;
    const char* featured_mesh_prefix;
    bool centre_is_featured;
};
constexpr BenchmarkScene kBenchmarkScenes[] = {
    {"sphereflake", "flake", true}, {"terrain", "terrain", true}, {"instances", "", false}};

bool is_featured(const Scene& scene, const SceneGeometry& geometry, uint32_t prim, const std::string& prefix) {
    const std::string& mesh = scene.meshes[scene.instances[geometry.triangle_instance[prim]].mesh].name;
    if (prefix.empty()) return mesh != "ground";
    return mesh.rfind(prefix, 0) == 0;
}

TEST(BuiltinBenchmarkScenes, AreListedAndLoad) {
    const auto names = builtin_scene_names();
    for (const BenchmarkScene& b : kBenchmarkScenes) {
        EXPECT_NE(std::find(names.begin(), names.end(), b.name), names.end()) << b.name;
        Scene scene = load_scene(std::string("builtin:") + b.name);  // finalize() validates every mesh
        EXPECT_EQ(scene.source, std::string("builtin:") + b.name);
        EXPECT_FALSE(scene.lights.empty()) << b.name;
        ASSERT_TRUE(scene.camera.has_value()) << b.name;
        for (const Material& m : scene.materials) {
            EXPECT_EQ(m.metallic, 0.0f) << b.name << " " << m.name;
            EXPECT_EQ(m.transmission, 0.0f) << b.name << " " << m.name;
            EXPECT_FALSE(m.is_emissive()) << b.name << " " << m.name;
        }
    }
}

TEST(BuiltinBenchmarkScenes, TriangleCountsAreInTheBenchmarkRange) {
    for (const BenchmarkScene& b : kBenchmarkScenes) {
        const size_t count = make_builtin_scene(b.name).triangle_count();
        EXPECT_GE(count, 100000u) << b.name;
        EXPECT_LE(count, 400000u) << b.name;
    }
    // 1 + 9 + 81 + 729 + 6561 spheres of slices * (2 * stacks - 2) triangles, and the ground.
    EXPECT_EQ(make_builtin_scene("sphereflake").triangle_count(),
              64u * 62u + 9u * 32u * 30u + 81u * 16u * 14u + 729u * 12u * 10u + 6561u * 6u * 4u + 2u);
    // 384 x 384 cells and the water plane.
    EXPECT_EQ(make_builtin_scene("terrain").triangle_count(), 2u * 384u * 384u + 2u);
    Scene instances = make_builtin_scene("instances");
    EXPECT_EQ(instances.instances.size(), 401u);  // 400 objects and the ground
    EXPECT_LT(instances.meshes.size(), 16u);      // few meshes, many instances
}

TEST(BuiltinBenchmarkScenes, GenerationIsDeterministic) {
    for (const BenchmarkScene& b : kBenchmarkScenes) {
        const SceneGeometry first = SceneGeometry::build(make_builtin_scene(b.name));
        const SceneGeometry second = SceneGeometry::build(make_builtin_scene(b.name));
        ASSERT_EQ(first.size(), second.size()) << b.name;
        EXPECT_EQ(std::memcmp(first.triangles.data(), second.triangles.data(), first.size() * sizeof(Triangle)), 0)
            << b.name;
        EXPECT_EQ(first.material, second.material) << b.name;
        EXPECT_EQ(first.triangle_instance, second.triangle_instance) << b.name;
    }
}

TEST(BuiltinBenchmarkScenes, GeometryIsFiniteAndRestsOnTheGround) {
    for (const BenchmarkScene& b : kBenchmarkScenes) {
        const Scene scene = make_builtin_scene(b.name);
        for (const Mesh& mesh : scene.meshes) {
            ASSERT_EQ(mesh.normals.size(), mesh.positions.size()) << b.name << " " << mesh.name;
            for (size_t i = 0; i < mesh.positions.size(); ++i) {
                ASSERT_TRUE(is_finite(mesh.positions[i])) << b.name << " " << mesh.name << " vertex " << i;
                ASSERT_NEAR(length(mesh.normals[i]), 1.0f, 1e-3f) << b.name << " " << mesh.name << " normal " << i;
            }
        }
        // Nothing below the ground plane y = 0 (the terrain's lowest point is 0 by construction).
        const SceneGeometry geometry = SceneGeometry::build(scene);
        EXPECT_GT(geometry.bounds.lo.y, -1e-4f) << b.name;
        EXPECT_LT(geometry.bounds.lo.y, 1e-4f) << b.name;
        EXPECT_GT(geometry.bounds.hi.y, 2.0f) << b.name;
    }
}

TEST(BuiltinBenchmarkScenes, TerrainNormalsPointUpAndMatchTheSurface) {
    const Scene scene = make_builtin_scene("terrain");
    const Mesh& terrain = scene.meshes[scene.instances[0].mesh];
    ASSERT_EQ(terrain.name, "terrain");
    for (const Vec3f& n : terrain.normals) ASSERT_GT(n.y, 0.0f);
    // Vertex normals come from central differences of the heights: on average
    // they agree closely with the faces around them.
    double agreement = 0.0;
    for (size_t t = 0; t < terrain.triangle_count(); ++t) {
        const uint32_t a = terrain.indices[3 * t], b = terrain.indices[3 * t + 1], c = terrain.indices[3 * t + 2];
        const Vec3f face = normalize(cross(terrain.positions[b] - terrain.positions[a],
                                           terrain.positions[c] - terrain.positions[a]));
        ASSERT_GT(face.y, 0.0f) << "triangle " << t;
        agreement += dot(face, normalize(terrain.normals[a] + terrain.normals[b] + terrain.normals[c]));
    }
    EXPECT_GT(agreement / double(terrain.triangle_count()), 0.95);
}

TEST(BuiltinBenchmarkScenes, CameraSeesTheFeaturedGeometry) {
    constexpr int kWidth = 64, kHeight = 48;
    for (const BenchmarkScene& b : kBenchmarkScenes) {
        const Scene scene = make_builtin_scene(b.name);
        const SceneGeometry geometry = SceneGeometry::build(scene);
        BuildOptions options;
        options.threads = 1;
        const auto accel = build_accel(geometry, options);
        const CameraFrame frame = CameraFrame::make(*scene.camera, kWidth, kHeight);

        const Hit centre = accel->intersect(frame.generate(0.5f * kWidth, 0.5f * kHeight, kWidth, kHeight));
        ASSERT_TRUE(centre.found()) << b.name;
        if (b.centre_is_featured) EXPECT_TRUE(is_featured(scene, geometry, centre.prim, b.featured_mesh_prefix)) << b.name;

        // Most of the image shows the scene, and a good part of it the featured geometry.
        int hits = 0, featured = 0;
        for (int y = 0; y < kHeight; ++y) {
            for (int x = 0; x < kWidth; ++x) {
                const Hit hit = accel->intersect(frame.generate(float(x) + 0.5f, float(y) + 0.5f, kWidth, kHeight));
                if (!hit.found()) continue;
                ++hits;
                featured += is_featured(scene, geometry, hit.prim, b.featured_mesh_prefix) ? 1 : 0;
            }
        }
        EXPECT_GT(hits, kWidth * kHeight / 2) << b.name;
        EXPECT_GT(featured, kWidth * kHeight / 5) << b.name;
    }
}

}  // namespace
}  // namespace rf
