// Built-in scenes: every name loads and validates, the Cornell box and the
// sphere field have the geometry, materials, lights and cameras they promise,
// and generation is deterministic.
#include <gtest/gtest.h>

#include <chrono>
#include <cstring>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"

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

TEST(BuiltinScenes, GenerationIsFast) {
    const auto start = std::chrono::steady_clock::now();
    Scene scene = make_builtin_scene("spheres");
    Scene cornell = make_builtin_scene("cornell");
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(ms, 500.0);  // ~10 ms in a release build; generous for debug builds
}

TEST(BuiltinScenes, TinyScenes) {
    EXPECT_EQ(make_builtin_scene("triangle").triangle_count(), 1u);
    EXPECT_EQ(make_builtin_scene("plane").triangle_count(), 2u);
    EXPECT_EQ(make_builtin_scene("cube").triangle_count(), 12u);
    Box3f cube = make_builtin_scene("cube").bounds();
    expect_vec(cube.lo, {-0.5f, -0.5f, -0.5f});
    expect_vec(cube.hi, {0.5f, 0.5f, 0.5f});
}

}  // namespace
}  // namespace rf
