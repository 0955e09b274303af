// Built-in scenes: every name loads and validates, the Cornell box and the
// sphere field have the geometry, materials, lights and cameras they promise,
// the procedural benchmark scenes (sphereflake, terrain, instances) are large,
// finite, lit and framed by their cameras, and generation is deterministic.
// The path-tracing scenes (furnace, material-spheres, sky-sphere) have the
// materials, emitters and environment they promise, and the procedural sky
// is finite, positive, brightest at the sun and calibrated as documented.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/camera.h"
#include "rayforge/scene/scene_geometry.h"
#include "io/procedural_sky.h"
#include "math/color.h"
#include "test_paths.h"

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


// ---- Path-tracing scenes --------------------------------------------------

// The Cornell box's walls are Lambertian (no specular layer), its light
// emits from the face towards the room only.
TEST(BuiltinScenes, CornellWallsAreLambertianAndTheLightOneSided) {
    const Scene scene = load_scene("builtin:cornell");
    for (const Material& m : scene.materials) {
        if (m.name == "white" || m.name == "red" || m.name == "green") EXPECT_EQ(m.specular, 0.0f) << m.name;
        if (m.is_emissive()) EXPECT_FALSE(m.two_sided_emission) << m.name;
    }
}

const Material* find_material(const Scene& scene, const std::string& name) {
    for (const Material& m : scene.materials)
        if (m.name == name) return &m;
    return nullptr;
}

// The mesh (by name) that the first hit of the ray from the camera's eye
// towards `point` belongs to; "" on a miss.
std::string first_mesh_seen(const Scene& scene, const SceneGeometry& geometry, const Accel& accel, Vec3f point) {
    Ray ray;
    ray.org = scene.camera->eye;
    ray.dir = point - scene.camera->eye;
    const Hit hit = accel.intersect(ray);
    if (!hit.found()) return "";
    return scene.meshes[scene.instances[geometry.triangle_instance[hit.prim]].mesh].name;
}

// Centre of a mesh's bounds (its instances here are the identity).
Vec3f mesh_centre(const Mesh& mesh) {
    Box3f b;
    for (const Vec3f& p : mesh.positions) b.extend(p);
    return (b.lo + b.hi) * 0.5f;
}

const Mesh* find_mesh(const Scene& scene, const std::string& name) {
    for (const Mesh& m : scene.meshes)
        if (m.name == name) return &m;
    return nullptr;
}

TEST(PathTracingScenes, AreListed) {
    const auto names = builtin_scene_names();
    for (const char* name : {"furnace", "material-spheres", "sky-sphere"})
        EXPECT_NE(std::find(names.begin(), names.end(), name), names.end()) << name;
}

TEST(PathTracingScenes, FurnaceIsAWhiteLambertSphereInAUniformEnvironment) {
    const Scene scene = load_scene("builtin:furnace");  // finalized
    EXPECT_EQ(scene.triangle_count(), 64u * (2u * 32u - 2u));
    ASSERT_EQ(scene.materials.size(), 1u);
    const Material& m = scene.materials[0];
    EXPECT_EQ(m.base_color, Vec3f(1.0f));
    EXPECT_EQ(m.metallic, 0.0f);
    EXPECT_EQ(m.roughness, 1.0f);
    EXPECT_EQ(m.ior, 1.0f);
    EXPECT_EQ(m.transmission, 0.0f);
    EXPECT_FALSE(m.is_emissive());
    EXPECT_EQ(m.base_color_texture, kNoTexture);
    EXPECT_TRUE(scene.lights.empty());
    EXPECT_EQ(scene.environment.color, Vec3f(1.0f));
    EXPECT_EQ(scene.environment.strength, 1.0f);
    EXPECT_EQ(scene.environment.texture, -1);
    // A unit sphere with smooth normals equal to the positions.
    ASSERT_EQ(scene.meshes.size(), 1u);
    const Mesh& sphere = scene.meshes[0];
    ASSERT_EQ(sphere.normals.size(), sphere.positions.size());
    for (size_t i = 0; i < sphere.positions.size(); ++i) {
        ASSERT_NEAR(length(sphere.positions[i]), 1.0f, 1e-5f) << i;
        ASSERT_NEAR(length(sphere.normals[i] - sphere.positions[i]), 0.0f, 1e-5f) << i;
    }
    // The camera frames the whole sphere: the centre ray hits it, the corners miss.
    const SceneGeometry geometry = SceneGeometry::build(scene);
    const auto accel = build_accel(geometry, BuildOptions{});
    const CameraFrame frame = CameraFrame::make(*scene.camera, 64, 64);
    EXPECT_TRUE(accel->intersect(frame.generate(32.0f, 32.0f, 64, 64)).found());
    EXPECT_FALSE(accel->intersect(frame.generate(0.5f, 0.5f, 64, 64)).found());
    EXPECT_FALSE(accel->intersect(frame.generate(63.5f, 63.5f, 64, 64)).found());
}

TEST(PathTracingScenes, MaterialSpheresHasGlassMetalsPlasticAnAreaLightAndTheSky) {
    const Scene scene = load_scene("builtin:material-spheres");
    struct Expected {
        const char* name;
        float metallic, roughness, transmission;
    };
    const Expected expected[] = {{"smooth_glass", 0, 0.0f, 1},  {"rough_glass", 0, 0.3f, 1},
                                 {"gold", 1, 0.05f, 0},          {"brushed_copper", 1, 0.4f, 0},
                                 {"glossy_plastic", 0, 0.3f, 0}, {"diffuse", 0, 1.0f, 0}};
    for (const Expected& e : expected) {
        const Material* m = find_material(scene, e.name);
        ASSERT_NE(m, nullptr) << e.name;
        EXPECT_EQ(m->metallic, e.metallic) << e.name;
        EXPECT_FLOAT_EQ(m->roughness, e.roughness) << e.name;
        EXPECT_EQ(m->transmission, e.transmission) << e.name;
        if (e.transmission > 0) EXPECT_EQ(m->ior, 1.5f) << e.name;
        EXPECT_FALSE(m->is_emissive()) << e.name;
    }
    expect_vec(find_material(scene, "gold")->base_color, {1.0f, 0.78f, 0.34f});
    // The matte sphere is Lambertian; the plastic keeps its specular coat.
    EXPECT_EQ(find_material(scene, "diffuse")->specular, 0.0f);
    EXPECT_EQ(find_material(scene, "glossy_plastic")->specular, 1.0f);

    // Exactly one emitter: a quad above the spheres, facing down, strength 10..20.
    const SceneGeometry geometry = SceneGeometry::build(scene);
    int emissive_triangles = 0;
    for (size_t t = 0; t < geometry.size(); ++t) {
        const Material& m = scene.materials[geometry.material[t]];
        if (!m.is_emissive()) continue;
        ++emissive_triangles;
        EXPECT_GE(m.emission_strength, 10.0f);
        EXPECT_LE(m.emission_strength, 20.0f);
        EXPECT_FALSE(m.two_sided_emission);
        const Mesh& mesh = scene.meshes[scene.instances[geometry.triangle_instance[t]].mesh];
        ASSERT_EQ(mesh.name, "area_light");
        const uint32_t local = geometry.local_triangle[t];
        const Vec3f a = mesh.positions[mesh.indices[3 * local]], b = mesh.positions[mesh.indices[3 * local + 1]],
                    c = mesh.positions[mesh.indices[3 * local + 2]];
        EXPECT_LT(cross(b - a, c - a).y, 0.0f) << "the light must face down";
        EXPECT_GT(a.y, 2.0f);
    }
    EXPECT_EQ(emissive_triangles, 2);
    EXPECT_TRUE(scene.lights.empty());

    ASSERT_GE(scene.environment.texture, 0);
    ASSERT_LT(size_t(scene.environment.texture), scene.textures.size());
    const Texture& sky = scene.textures[size_t(scene.environment.texture)];
    EXPECT_EQ(sky.name, "builtin:sky");
    EXPECT_EQ(sky.encoding, TextureEncoding::LinearFloat);
    EXPECT_FLOAT_EQ(scene.environment.strength, 0.5f);

    // The floor is a checkerboard of two materials and every sphere is in view.
    const Mesh* floor = find_mesh(scene, "floor");
    ASSERT_NE(floor, nullptr);
    std::vector<uint32_t> floor_materials = floor->material_ids;
    std::sort(floor_materials.begin(), floor_materials.end());
    floor_materials.erase(std::unique(floor_materials.begin(), floor_materials.end()), floor_materials.end());
    EXPECT_EQ(floor_materials.size(), 2u);
    const auto accel = build_accel(geometry, BuildOptions{});
    for (const Expected& e : expected) {
        const Mesh* sphere = find_mesh(scene, e.name);
        ASSERT_NE(sphere, nullptr) << e.name;
        EXPECT_EQ(first_mesh_seen(scene, geometry, *accel, mesh_centre(*sphere)), e.name);
    }
}

TEST(PathTracingScenes, SkySphereIsLitOnlyByTheProceduralSky) {
    const Scene scene = load_scene("builtin:sky-sphere");
    EXPECT_TRUE(scene.lights.empty());
    for (const Material& m : scene.materials) EXPECT_FALSE(m.is_emissive()) << m.name;
    ASSERT_GE(scene.environment.texture, 0);
    ASSERT_LT(size_t(scene.environment.texture), scene.textures.size());
    const Texture& sky = scene.textures[size_t(scene.environment.texture)];
    EXPECT_EQ(sky.name, "builtin:sky");
    EXPECT_EQ(sky.encoding, TextureEncoding::LinearFloat);
    EXPECT_EQ(sky.channels, 3);
    EXPECT_GT(scene.environment.strength, 0.0f);
    // Everything rests on the ground y = 0 and each object is in view.
    const SceneGeometry geometry = SceneGeometry::build(scene);
    EXPECT_NEAR(geometry.bounds.lo.y, 0.0f, 1e-4f);
    const auto accel = build_accel(geometry, BuildOptions{});
    for (const char* name : {"white_sphere", "metal_sphere", "glossy_sphere"})
        EXPECT_EQ(first_mesh_seen(scene, geometry, *accel, mesh_centre(*find_mesh(scene, name))), name);
    EXPECT_EQ(first_mesh_seen(scene, geometry, *accel, scene.instances.back().transform.transform_point(Vec3f(0.0f))),
              "cube");
}

TEST(PathTracingScenes, GenerationIsDeterministic) {
    for (const char* name : {"furnace", "material-spheres", "sky-sphere"}) {
        const Scene a = make_builtin_scene(name), b = make_builtin_scene(name);
        const SceneGeometry ga = SceneGeometry::build(a), gb = SceneGeometry::build(b);
        ASSERT_EQ(ga.size(), gb.size()) << name;
        EXPECT_EQ(std::memcmp(ga.triangles.data(), gb.triangles.data(), ga.size() * sizeof(Triangle)), 0) << name;
        ASSERT_EQ(a.textures.size(), b.textures.size()) << name;
        for (size_t t = 0; t < a.textures.size(); ++t) EXPECT_EQ(a.textures[t].texels_f, b.textures[t].texels_f) << name;
    }
}

// ---- Procedural sky -------------------------------------------------------

constexpr double kPiD = 3.14159265358979323846;

Vec3f texel(const Texture& t, int i, int j) {
    const float* p = &t.texels_f[(size_t(j) * size_t(t.width) + size_t(i)) * 3];
    return {p[0], p[1], p[2]};
}

// Irradiance on a horizontal plane facing +y from the map as a piecewise
// constant function, split into the sun texels (luminance above `sun_threshold`)
// and the rest; per-texel weight = exact integral of max(cos, 0) over its solid angle.
void horizontal_irradiance(const Texture& t, float sun_threshold, double& sky, double& sun, double& sun_solid_angle) {
    sky = sun = sun_solid_angle = 0.0;
    for (int j = 0; j < t.height; ++j) {
        const double c0 = std::fmax(std::cos(kPiD * j / t.height), 0.0);
        const double c1 = std::fmax(std::cos(kPiD * (j + 1) / t.height), 0.0);
        const double weight = (2.0 * kPiD / t.width) * 0.5 * (c0 * c0 - c1 * c1);
        const double solid_angle = (2.0 * kPiD / t.width) * (std::cos(kPiD * j / t.height) - std::cos(kPiD * (j + 1) / t.height));
        for (int i = 0; i < t.width; ++i) {
            const float l = luminance(texel(t, i, j));
            if (l > sun_threshold) {
                sun += l * weight;
                sun_solid_angle += solid_angle;
            } else {
                sky += l * weight;
            }
        }
    }
}

TEST(ProceduralSky, TexelsAreFiniteAndPositive) {
    const Texture sky = make_sky_texture();
    EXPECT_EQ(sky.width, 512);
    EXPECT_EQ(sky.height, 256);
    EXPECT_EQ(sky.channels, 3);
    EXPECT_EQ(sky.encoding, TextureEncoding::LinearFloat);
    ASSERT_EQ(sky.texels_f.size(), size_t(512) * 256 * 3);
    for (size_t k = 0; k < sky.texels_f.size(); ++k) {
        ASSERT_TRUE(std::isfinite(sky.texels_f[k])) << k;
        ASSERT_GT(sky.texels_f[k], 0.0f) << k;
    }
}

TEST(ProceduralSky, DirectionConventionMatchesTheMapping) {
    expect_vec(equirect_direction(0.5f, 0.0f), {0, 1, 0});
    expect_vec(equirect_direction(0.5f, 0.5f), {0, 0, -1});
    expect_vec(equirect_direction(0.75f, 0.5f), {1, 0, 0});
    expect_vec(equirect_direction(0.25f, 0.5f), {-1, 0, 0});
    expect_vec(sky_sun_direction(90.0f, 0.0f), {0, 1, 0});
    expect_vec(sky_sun_direction(0.0f, 0.0f), {0, 0, -1});
    expect_vec(sky_sun_direction(0.0f, 90.0f), {1, 0, 0});
    // u = 0.5 + atan2(x, -z) / 2pi, v = acos(y) / pi invert equirect_direction.
    for (float u : {0.1f, 0.37f, 0.5f, 0.8f})
        for (float v : {0.05f, 0.3f, 0.5f, 0.9f}) {
            const Vec3f d = equirect_direction(u, v);
            EXPECT_NEAR(0.5f + std::atan2(d.x, -d.z) / (2.0f * float(kPiD)), u, 1e-5f);
            EXPECT_NEAR(std::acos(d.y) / float(kPiD), v, 1e-5f);
        }
}

TEST(ProceduralSky, BrightestAroundTheSunAndBlueOverhead) {
    for (const auto& [elevation, azimuth] : {std::pair{35.0f, 30.0f}, std::pair{10.0f, -120.0f}, std::pair{70.0f, 200.0f}}) {
        const Texture sky = make_sky_texture(256, 128, elevation, azimuth);
        const Vec3f sun = sky_sun_direction(elevation, azimuth);
        int best_i = 0, best_j = 0;
        float best = -1.0f;
        for (int j = 0; j < sky.height; ++j)
            for (int i = 0; i < sky.width; ++i)
                if (luminance(texel(sky, i, j)) > best) {
                    best = luminance(texel(sky, i, j));
                    best_i = i;
                    best_j = j;
                }
        const Vec3f d = equirect_direction((best_i + 0.5f) / sky.width, (best_j + 0.5f) / sky.height);
        // Within the disk plus half a texel diagonal (1.4 x 0.7 degrees here).
        const float angle_deg = std::acos(std::fmin(dot(d, sun), 1.0f)) * 180.0f / float(kPiD);
        EXPECT_LT(angle_deg, kSkySunAngularRadiusDegrees + 1.0f) << elevation << " " << azimuth;
        EXPECT_GT(best, 100.0f) << "the sun is very bright";
        // Sky: the zenith is bluer than the horizon; the ground is darker than the sky.
        const Vec3f zenith = texel(sky, sky.width / 4, 0);
        const Vec3f horizon = texel(sky, sky.width / 4, sky.height / 2 - 1);
        const Vec3f ground = texel(sky, sky.width / 4, sky.height - 1);
        EXPECT_GT(zenith.z / zenith.x, horizon.z / horizon.x);
        EXPECT_LT(luminance(ground), 0.5f * luminance(horizon));
        EXPECT_LT(luminance(ground), 0.5f * luminance(zenith));
    }
}

TEST(ProceduralSky, SunGivesThreeTimesTheSkyIrradiance) {
    const float elevation = 35.0f;
    const Texture sky = make_sky_texture(512, 256, elevation, 30.0f);
    double e_sky = 0, e_sun = 0, sun_solid_angle = 0;
    horizontal_irradiance(sky, 100.0f, e_sky, e_sun, sun_solid_angle);
    // Exact on the texture (calibrated on it), up to float sums.
    EXPECT_NEAR(e_sun / e_sky, double(kSkySunToSkyIrradiance), 1e-3);
    // The sky alone is a plausible daylight sky: between a uniform 0.3 and 1 (pi * L).
    EXPECT_GT(e_sky, 0.3 * kPiD);
    EXPECT_LT(e_sky, 1.0 * kPiD);
    // The texels approximate the analytic disk: solid angle 2 pi (1 - cos r)
    // within 25% (a disk about 4 texels across).
    const double r = kSkySunAngularRadiusDegrees * kPiD / 180.0;
    const double disk = 2.0 * kPiD * (1.0 - std::cos(r));
    EXPECT_NEAR(sun_solid_angle / disk, 1.0, 0.25);
    // A tiny map keeps a (one-texel) sun even at a grazing elevation, still calibrated.
    const Texture tiny = make_sky_texture(16, 8, 1.0f, 0.0f);
    horizontal_irradiance(tiny, 100.0f, e_sky, e_sun, sun_solid_angle);
    EXPECT_GT(sun_solid_angle, 0.0);
    EXPECT_NEAR(e_sun / e_sky, double(kSkySunToSkyIrradiance), 1e-3);
}

TEST(ProceduralSky, InvalidParametersAreErrors) {
    EXPECT_THROW((void)make_sky_texture(4, 2), Error);
    EXPECT_THROW((void)make_sky_texture(512, 256, 0.0f, 0.0f), Error);
    EXPECT_THROW((void)make_sky_texture(512, 256, 91.0f, 0.0f), Error);
    EXPECT_THROW((void)make_sky_texture(512, 256, NAN, 0.0f), Error);
    EXPECT_THROW((void)make_sky_texture(512, 256, 30.0f, INFINITY), Error);
}

std::string write_json(const std::string& dir, const std::string& text) {
    const std::string path = dir + "/scene.json";
    std::ofstream(path) << text;
    return path;
}

TEST(ProceduralSky, JsonEnvironmentMapBuiltinSky) {
    const std::string dir = test::temp_dir("procedural_sky_json");
    const std::string mesh = R"("meshes": [{"file": "builtin:triangle"}])";
    Scene scene = load_scene(write_json(
        dir, "{" + mesh + R"(, "environment": {"map": "builtin:sky", "strength": 0.5, "sun_elevation_deg": 60, "sun_azimuth_deg": -45}})"));
    ASSERT_GE(scene.environment.texture, 0);
    const Texture& sky = scene.textures[size_t(scene.environment.texture)];
    EXPECT_EQ(sky.name, "builtin:sky");
    EXPECT_FLOAT_EQ(scene.environment.strength, 0.5f);
    EXPECT_EQ(sky.texels_f, make_sky_texture(512, 256, 60.0f, -45.0f).texels_f);
    // Defaults: elevation 35, azimuth 30.
    scene = load_scene(write_json(dir, "{" + mesh + R"(, "environment": {"map": "builtin:sky"}})"));
    ASSERT_GE(scene.environment.texture, 0);
    EXPECT_EQ(scene.textures[size_t(scene.environment.texture)].texels_f, make_sky_texture().texels_f);
    // Sun keys need the procedural sky; a bad elevation is an error naming its key.
    EXPECT_THROW(load_scene(write_json(dir, "{" + mesh + R"(, "environment": {"sun_elevation_deg": 30}})")), Error);
    try {
        load_scene(write_json(dir, "{" + mesh + R"(, "environment": {"map": "builtin:sky", "sun_elevation_deg": -5}})"));
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("sun_elevation_deg"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace rf
