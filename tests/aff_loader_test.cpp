// BART AFF loading: polygons, meshes with includes and static transforms,
// keyframe animation evaluated at one time, textures, malformed files
// (fixtures: tests/data/aff/), and the three BART scenes of ../shared when present.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/scene_io.h"
#include "scene_load_error.h"
#include "test_paths.h"

namespace rf {
namespace {

namespace fs = std::filesystem;

std::string aff_fixture(const std::string& name) { return test::data_path("aff/" + name); }

void expect_near3(Vec3f actual, Vec3f expected, float tolerance = 1e-4f) {
    EXPECT_NEAR(actual.x, expected.x, tolerance);
    EXPECT_NEAR(actual.y, expected.y, tolerance);
    EXPECT_NEAR(actual.z, expected.z, tolerance);
}

Vec3f translation_of(const Affine3f& a) { return {a.m[0][3], a.m[1][3], a.m[2][3]}; }

using test::load_error;

void write_file(const fs::path& path, const std::string& text) {
    std::ofstream out(path, std::ios::binary);
    out << text;
}

TEST(AffLoader, PolygonsViewpointLightsAndMaterials) {
    Scene scene = load_scene(aff_fixture("polygon.aff"));
    EXPECT_EQ(scene.triangle_count(), 3u);  // quad fan (2) + patch (1)
    ASSERT_TRUE(scene.camera.has_value());
    expect_near3(scene.camera->eye, {0, 0, 5});
    expect_near3(scene.camera->target, {0, 0, 0});
    EXPECT_FLOAT_EQ(scene.camera->vfov_degrees, 40.0f);
    EXPECT_EQ(scene.render_settings.width, 64);
    EXPECT_EQ(scene.render_settings.height, 48);
    expect_near3(scene.environment.color, {0.1f, 0.2f, 0.3f});
    ASSERT_EQ(scene.lights.size(), 2u);
    expect_near3(scene.lights[0].position, {0, 5, 5});
    expect_near3(scene.lights[0].color, {0.5f, 0.5f, 0.5f});
    expect_near3(scene.lights[1].color, {1, 1, 1});  // no color given: white
    EXPECT_GT(scene.lights[0].intensity, 0.0f);

    ASSERT_EQ(scene.meshes.size(), 1u);  // loose polygons of one block share a mesh
    const Mesh& mesh = scene.meshes[0];
    ASSERT_EQ(mesh.material_ids.size(), 3u);
    const Material& red = scene.materials[mesh.material_ids[0]];
    const Material& green = scene.materials[mesh.material_ids[2]];
    expect_near3(red.base_color, {0.8f, 0.0f, 0.0f});  // color * Kd
    expect_near3(green.base_color, {0.0f, 1.0f, 0.0f});
    EXPECT_FLOAT_EQ(red.specular, 0.2f);  // NFF Ks: the specular layer's strength
    EXPECT_NEAR(red.roughness, std::pow(2.0f / 12.0f, 0.25f), 1e-6f);  // shine 10 (as MTL's Ns)
    EXPECT_FLOAT_EQ(green.specular, 0.0f);  // Ks = 0: pure Lambertian
    EXPECT_EQ(mesh.material_ids[0], mesh.material_ids[1]);
    // The patch's normals (0,0,2) come out unit length.
    ASSERT_EQ(mesh.normals.size(), mesh.positions.size());
    expect_near3(mesh.normals[mesh.indices[6]], {0, 0, 1});
    expect_near3(mesh.positions[mesh.indices[6]], {0, 0, 1});
}

TEST(AffLoader, MirrorAndGlassFromNffMaterials) {
    const fs::path dir = test::temp_dir("aff_mirror_glass");
    write_file(dir / "m.aff",
               "f 1 1 1 0.1 0.9 1000 0 1\np 3\n0 0 0\n1 0 0\n0 1 0\n"       // Ks dominates: mirror
               "f 1 1 1 0 0.1 100 0.9 1.33\np 3\n0 0 1\n1 0 1\n0 1 1\n"     // T > 0: glass
               "f 1 1 1 0.5 0 0 0.5 1\np 3\n0 0 2\n1 0 2\n0 1 2\n");        // index 1: index-matched
    Scene scene = load_scene((dir / "m.aff").string());
    const Mesh& mesh = scene.meshes[0];
    ASSERT_EQ(mesh.material_ids.size(), 3u);
    const Material& mirror = scene.materials[mesh.material_ids[0]];
    EXPECT_FLOAT_EQ(mirror.metallic, 1.0f);
    expect_near3(mirror.base_color, {0.9f, 0.9f, 0.9f});
    const Material& glass = scene.materials[mesh.material_ids[1]];
    EXPECT_FLOAT_EQ(glass.transmission, 0.9f);
    EXPECT_FLOAT_EQ(glass.ior, 1.33f);
    EXPECT_FLOAT_EQ(glass.roughness, 0.0f);
    EXPECT_FLOAT_EQ(scene.materials[mesh.material_ids[2]].ior, 1.0f);
}

// `am` scales every fm material's ambient color, wherever it appears (the
// last one counts); f materials have none; no am: no ambient term.
TEST(AffLoader, AmbientLightTimesFmAmbientColor) {
    const fs::path dir = test::temp_dir("aff_ambient");
    write_file(dir / "a.aff",
               "am 9 9 9\n"
               "fm 0.2 0.4 0.6  0.5 0.5 0.5  0 0 0  1 0 1\np 3\n0 0 0\n1 0 0\n0 1 0\n"
               "f 1 1 1 0.5 0 0 0 1\np 3\n0 0 1\n1 0 1\n0 1 1\n"
               "am 2 1 0.5\n");
    Scene scene = load_scene((dir / "a.aff").string());
    const Mesh& mesh = scene.meshes[0];
    ASSERT_EQ(mesh.material_ids.size(), 2u);
    expect_near3(scene.materials[mesh.material_ids[0]].ambient, {0.4f, 0.4f, 0.3f});
    expect_near3(scene.materials[mesh.material_ids[1]].ambient, {0, 0, 0});
    write_file(dir / "b.aff", "fm 0.2 0.4 0.6  0.5 0.5 0.5  0 0 0  1 0 1\np 3\n0 0 0\n1 0 0\n0 1 0\n");
    expect_near3(load_scene((dir / "b.aff").string()).materials[0].ambient, {0, 0, 0});
}

TEST(AffLoader, MeshIncludedTwiceWithStaticTransform) {
    Scene scene = load_scene(aff_fixture("mesh_include.aff"));
    EXPECT_EQ(scene.triangle_count(), 4u);  // each include is expanded again
    ASSERT_EQ(scene.meshes.size(), 2u);
    ASSERT_EQ(scene.instances.size(), 2u);
    const Mesh& mesh = scene.meshes[scene.instances[0].mesh];
    EXPECT_EQ(mesh.vertex_count(), 4u);
    ASSERT_EQ(mesh.uvs.size(), 4u);
    ASSERT_EQ(mesh.normals.size(), 4u);
    // T(10,0,0) * R_y(90) * S(2): (1,0,0) -> (2,0,0) -> (0,0,-2) -> (10,0,-2).
    const Affine3f& xf = scene.instances[0].transform;
    expect_near3(xf.transform_point(Vec3f{1, 0, 0}), {10, 0, -2});
    expect_near3(xf.transform_point(Vec3f{0, 1, 0}), {10, 2, 0});
    const Affine3f& plain = scene.instances[1].transform;
    expect_near3(plain.transform_point(Vec3f{1, 0, 0}), {1, 0, 0});
    // The included file's own fm applies to its mesh; its texture is found next to it.
    ASSERT_EQ(scene.textures.size(), 1u);
    EXPECT_EQ(scene.textures[0].width, 2);
    const Material& m = scene.materials[mesh.material_ids[0]];
    EXPECT_EQ(m.base_color_texture, 0);
    expect_near3(m.base_color, {1, 1, 1});
}

TEST(AffLoader, MissingTextureWarnsAndKeepsColor) {
    Scene scene = load_scene(aff_fixture("missing_texture.aff"));
    EXPECT_EQ(scene.triangle_count(), 1u);
    EXPECT_TRUE(scene.textures.empty());
    const Material& m = scene.materials[scene.meshes[0].material_ids[0]];
    EXPECT_EQ(m.base_color_texture, kNoTexture);
    expect_near3(m.base_color, {0.25f, 0.5f, 0.75f});
}

TEST(AffLoader, TexturesCanBeSkipped) {
    LoadOptions options;
    options.load_textures = false;
    Scene scene = load_aff(aff_fixture("mesh_include.aff"), options);
    EXPECT_TRUE(scene.textures.empty());
    EXPECT_EQ(scene.triangle_count(), 4u);
}

// The mesh instance whose mesh holds the single 'mover' triangle at (0,0,0),(1,0,0),(0,1,0).
const Instance* find_instance_with_vertex(const Scene& scene, Vec3f v, size_t triangles) {
    for (const Instance& inst : scene.instances) {
        const Mesh& mesh = scene.meshes[inst.mesh];
        if (mesh.triangle_count() != triangles) continue;
        for (Vec3f p : mesh.positions)
            if (p == v) return &inst;
    }
    return nullptr;
}

TEST(AffLoader, AnimationEvaluatedAtStartTime) {
    Scene scene = load_scene(aff_fixture("animated.aff"));  // 'a 1 3 10': time 1
    // mover 1 + hider 1 + tpa 1 + the tessellated sphere 528.
    EXPECT_EQ(scene.triangle_count(), 531u);
    const Instance* mover = find_instance_with_vertex(scene, Vec3f{1, 0, 0}, 1);
    ASSERT_NE(mover, nullptr);
    // At a key the spline passes through the key's value.
    expect_near3(translation_of(mover->transform), {5, 0, 0});
    expect_near3(mover->transform.transform_vector(Vec3f{1, 1, 1}), {1, 1, 1});
    // The camera follows 'k camera': the viewer looks down -z, rotated 90 degrees about y.
    ASSERT_TRUE(scene.camera.has_value());
    expect_near3(scene.camera->eye, {0, 0, 10});
    const Vec3f dir = normalize(scene.camera->target - scene.camera->eye);
    expect_near3(dir, {-1, 0, 0});
    expect_near3(normalize(scene.camera->up), {0, 1, 0});
    // tpa: halfway between its keys at times 0 and 2.
    bool found_tpa = false;
    for (const Mesh& mesh : scene.meshes)
        for (Vec3f p : mesh.positions)
            if (std::fabs(p.z - 2.0f) < 1e-5f) found_tpa = true;
    EXPECT_TRUE(found_tpa);
}

TEST(AffLoader, AnimationEvaluatedAtOtherTimes) {
    Scene at2 = load_aff_at_time(aff_fixture("animated.aff"), 2.0);
    EXPECT_EQ(at2.triangle_count(), 530u);  // 'hider' is invisible from time 1.5
    const Instance* mover = find_instance_with_vertex(at2, Vec3f{1, 0, 0}, 1);
    ASSERT_NE(mover, nullptr);
    expect_near3(translation_of(mover->transform), {7, 0, 0});
    expect_near3(mover->transform.transform_vector(Vec3f{1, 0, 0}), {2, 0, 0});

    // Between keys: Kochanek-Bartels with zero tension/continuity/bias (Catmull-Rom).
    Scene mid = load_aff_at_time(aff_fixture("animated.aff"), 1.5);
    mover = find_instance_with_vertex(mid, Vec3f{1, 0, 0}, 1);
    ASSERT_NE(mover, nullptr);
    EXPECT_NEAR(mover->transform.m[0][3], 6.1875f, 1e-4f);

    // Before the inner keys the animation is clamped to the second key.
    Scene early = load_aff_at_time(aff_fixture("animated.aff"), -10.0);
    mover = find_instance_with_vertex(early, Vec3f{1, 0, 0}, 1);
    ASSERT_NE(mover, nullptr);
    expect_near3(translation_of(mover->transform), {5, 0, 0});
}

TEST(AffLoader, MalformedFilesFailWithFileAndLine) {
    struct Case {
        const char* file;
        const char* expected;  // substring of the error
    };
    const Case cases[] = {
        {"unknown_keyword.aff", "unknown_keyword.aff:5: unknown keyword 'zz'"},
        {"count_too_big.aff", "count_too_big.aff:2: mesh vertex count 1000000000 exceeds what is left"},
        {"nan.aff", "nan.aff:3: non-finite number"},
        {"inf.aff", "inf.aff:3:"},
        {"index_out_of_range.aff", "index_out_of_range.aff:7: mesh vertex index 5 out of range"},
        {"cycle_a.aff", "include cycle"},
        {"missing_include.aff", "missing_include.aff:1: included file 'nowhere.aff' not found"},
        {"unclosed_block.aff", "unclosed_block.aff:1: transform block '{' is not closed"},
        {"stray_brace.aff", "stray_brace.aff:5: '}' without an open transform block"},
        {"too_few_keys.aff", "too_few_keys.aff:10: 'transl' of animation 'a' needs at least 4 keyframes"},
        {"bad_number.aff", "bad_number.aff:4: bad number 'x'"},
        {"zero_scale.aff", "zero_scale.aff:1: static transform has a zero scale"},
        {"no_geometry.aff", "no triangles"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.file);
        const std::string message = load_error(aff_fixture(std::string("bad/") + c.file));
        EXPECT_NE(message.find(c.expected), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

TEST(AffLoader, UnsupportedExtensionMessageListsAff) {
    const std::string dir = test::temp_dir("aff_ext");
    write_file(fs::path(dir) / "scene.nff", "p 3\n0 0 0\n1 0 0\n0 1 0\n");
    const std::string message = load_error((fs::path(dir) / "scene.nff").string());
    EXPECT_NE(message.find(".aff"), std::string::npos) << message;
}

TEST(AffLoader, IncludeDepthIsLimited) {
    const fs::path dir = test::temp_dir("aff_depth");
    for (int i = 0; i < 70; ++i)
        write_file(dir / ("f" + std::to_string(i) + ".aff"), "i 0 f" + std::to_string(i + 1) + ".aff\n");
    write_file(dir / "f70.aff", "p 3\n0 0 0\n1 0 0\n0 1 0\n");
    const std::string message = load_error((dir / "f0.aff").string());
    EXPECT_NE(message.find("nested deeper than 64"), std::string::npos) << message;
}

TEST(AffLoader, ExponentialIncludesAreStopped) {
    // Each file includes the next twice: 2^30 expansions if nothing stopped it.
    const fs::path dir = test::temp_dir("aff_exponential");
    for (int i = 0; i < 30; ++i) {
        const std::string next = "e" + std::to_string(i + 1) + ".aff";
        write_file(dir / ("e" + std::to_string(i) + ".aff"), "i 0 " + next + "\ni 0 " + next + "\n");
    }
    write_file(dir / "e30.aff", "p 3\n0 0 0\n1 0 0\n0 1 0\n");
    const auto start = std::chrono::steady_clock::now();
    const std::string message = load_error((dir / "e0.aff").string());
    EXPECT_NE(message.find("too many include expansions"), std::string::npos) << message;
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(20));
}

TEST(AffLoader, MemoryBudgetIsChecked) {
    const fs::path dir = test::temp_dir("aff_budget");
    std::string text = "m\nvertices 2000\n";
    for (int i = 0; i < 2000; ++i) text += "0 0 0\n";
    text += "triangles 0\n";
    write_file(dir / "big.aff", text);
    const size_t previous = set_memory_budget(4096);
    const std::string message = load_error((dir / "big.aff").string());
    set_memory_budget(previous);
    EXPECT_NE(message.find("over the memory budget"), std::string::npos) << message;
    EXPECT_NE(message.find("big.aff"), std::string::npos) << message;
}

// Every fixture (and the files it includes) cut at every length loads or throws rf::Error.
TEST(AffLoader, TruncatedFixturesLoadOrThrow) {
    const fs::path source = test::data_path("aff");
    for (const char* name : {"polygon.aff", "mesh_include.aff", "part.aff", "animated.aff", "missing_texture.aff"}) {
        const fs::path dir = test::temp_dir(std::string("aff_trunc_") + name);
        for (const auto& entry : fs::directory_iterator(source))
            if (entry.is_regular_file()) fs::copy_file(entry.path(), dir / entry.path().filename());
        std::ifstream in(source / name, std::ios::binary);
        const std::string full((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
        const std::string root = std::string(name) == "part.aff" ? "mesh_include.aff" : name;
        for (size_t cut = 0; cut < full.size(); ++cut) {
            write_file(dir / name, full.substr(0, cut));
            try {
                load_scene((dir / root).string());
            } catch (const Error&) {
                // expected for most cuts
            }
        }
    }
}

// The BART scenes of the shared scene set; counts from ../shared/scenes/MANIFEST.md.
TEST(AffLoader, SharedBartScenesHaveManifestTriangleCounts) {
    struct SharedScene {
        const char* path;
        size_t triangles;
    };
    const SharedScene scenes[] = {
        {"scenes/bart-kitchen/aff/kitchen.aff", 110561},
        {"scenes/bart-robot/aff/Robot.aff", 71708},
        // 11,308 polygons and triangles + 8 cones tessellated into 32 triangles each.
        {"scenes/bart-museum/aff/museum5.aff", 11308 + 8 * 32},
    };
    bool any = false;
    for (const SharedScene& s : scenes) {
        const std::string path = test::shared_path(s.path);
        if (path.empty()) continue;
        any = true;
        SCOPED_TRACE(s.path);
        Scene scene = load_scene(path);
        EXPECT_EQ(scene.triangle_count(), s.triangles);
        EXPECT_TRUE(scene.camera.has_value());
        EXPECT_FALSE(scene.lights.empty());
        EXPECT_FALSE(scene.textures.empty());
    }
    if (!any) GTEST_SKIP() << "../shared/scenes/bart-* not present";
}

}  // namespace
}  // namespace rf
