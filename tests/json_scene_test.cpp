// JSON scene files: merging referenced files (glTF, OBJ, PLY, built-ins) with
// transforms and material overrides, the scene-level settings, and errors
// that name the file and the JSON path. Fixtures: tests/data/json/.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "scene_load_error.h"
#include "test_paths.h"

namespace rf {
namespace {

constexpr float kEps = 1e-4f;

void expect_vec(Vec3f actual, Vec3f expected, float eps = kEps) {
    EXPECT_NEAR(actual.x, expected.x, eps);
    EXPECT_NEAR(actual.y, expected.y, eps);
    EXPECT_NEAR(actual.z, expected.z, eps);
}

std::string json_fixture(const std::string& name) { return test::data_path("json/" + name); }

using test::load_error;

// Writes `text` to a fresh file and returns its path.
std::string write_scene(const std::string& test_name, const std::string& text) {
    const std::string path = test::temp_dir(test_name) + "/scene.json";
    std::ofstream(path) << text;
    return path;
}

int material_index(const Scene& scene, const std::string& name) {
    for (size_t i = 0; i < scene.materials.size(); ++i)
        if (scene.materials[i].name == name) return int(i);
    return -1;
}

Box3f instance_bounds(const Scene& scene, size_t instance) {
    const Instance& inst = scene.instances[instance];
    return inst.transform.transform_box(scene.meshes[inst.mesh].bounds());
}

TEST(JsonScene, MergesReferencedFilesWithTransforms) {
    Scene scene = load_scene(json_fixture("scene.json"));
    // cube.glb, quad.obj (loaded once, placed twice), triangle.ply, builtin:triangle.
    EXPECT_EQ(scene.meshes.size(), 4u);
    ASSERT_EQ(scene.instances.size(), 5u);
    EXPECT_EQ(scene.triangle_count(), 12u + 2u + 2u + 1u + 1u);

    // cube.glb's own node transform (scale 2, z -5) composed with translate (10, 0, 0).
    Box3f cube = instance_bounds(scene, 0);
    expect_vec(cube.lo, {9, -1, -6});
    expect_vec(cube.hi, {11, 1, -4});
    // Scale 2, then 90 degrees about z (x -> y), then translate (0, 0, 1).
    Box3f quad = instance_bounds(scene, 1);
    expect_vec(quad.lo, {-2, 0, 1});
    expect_vec(quad.hi, {0, 2, 1});
    EXPECT_EQ(scene.instances[1].mesh, scene.instances[2].mesh);
    Box3f quad2 = instance_bounds(scene, 2);
    expect_vec(quad2.lo, {0, 5, 0});
    expect_vec(quad2.hi, {1, 6, 0});
    // Column-major matrix with translation (0, -3, 0).
    Box3f ply = instance_bounds(scene, 3);
    expect_vec(ply.lo, {0, -3, 0});
    expect_vec(ply.hi, {1, -3, 1});

    Box3f all = scene.bounds();
    expect_vec(all.lo, {-2, -3, -6});
    expect_vec(all.hi, {11, 6, 1});
}

TEST(JsonScene, MaterialOverridesAndDefinitions) {
    Scene scene = load_scene(json_fixture("scene.json"));
    const int red = material_index(scene, "red");
    const int lamp = material_index(scene, "lamp");
    ASSERT_GE(red, 0);
    ASSERT_GE(lamp, 0);
    expect_vec(scene.materials[size_t(red)].base_color, {0.8f, 0.1f, 0.1f});
    EXPECT_FLOAT_EQ(scene.materials[size_t(red)].roughness, 0.5f);
    const Material& lamp_material = scene.materials[size_t(lamp)];
    EXPECT_TRUE(lamp_material.is_emissive());
    EXPECT_FLOAT_EQ(lamp_material.emission_strength, 10.0f);
    ASSERT_NE(lamp_material.base_color_texture, kNoTexture);
    EXPECT_EQ(scene.textures[size_t(lamp_material.base_color_texture)].encoding, TextureEncoding::Srgb8);

    for (uint32_t id : scene.meshes[scene.instances[1].mesh].material_ids) EXPECT_EQ(id, uint32_t(red));
    for (uint32_t id : scene.meshes[scene.instances[3].mesh].material_ids) EXPECT_EQ(id, uint32_t(lamp));
    // Every material id is valid after re-indexing.
    for (const Mesh& mesh : scene.meshes)
        for (uint32_t id : mesh.material_ids) EXPECT_LT(id, scene.materials.size());
}

// specular / specular_color, and the emission side: one-sided by default,
// two_sided_emission or its older name double_sided turning both faces on.
TEST(JsonScene, SpecularLayerAndEmissionSides) {
    const std::string path = write_scene("json_scene_specular", R"({
        "meshes": [{"file": "builtin:triangle"}],
        "materials": {
            "lambert": {"base_color": [0.5, 0.5, 0.5], "specular": 0},
            "tinted": {"specular": 0.25, "specular_color": [1, 0.5, 0]},
            "plain": {"emission": [1, 1, 1]},
            "both": {"emission": [1, 1, 1], "two_sided_emission": true},
            "legacy": {"emission": [1, 1, 1], "double_sided": true},
            "agreeing": {"two_sided_emission": false, "double_sided": false},
            "ambient": {"ambient": [0.1, 0.2, 0.3]}
        }})");
    Scene scene = load_scene(path);
    auto m = [&](const char* name) { return scene.materials[size_t(material_index(scene, name))]; };
    EXPECT_FLOAT_EQ(m("lambert").specular, 0.0f);
    EXPECT_FLOAT_EQ(m("tinted").specular, 0.25f);
    expect_vec(m("tinted").specular_color, {1.0f, 0.5f, 0.0f});
    EXPECT_FLOAT_EQ(m("plain").specular, 1.0f);  // the glTF default
    EXPECT_FALSE(m("plain").two_sided_emission);
    EXPECT_TRUE(m("both").two_sided_emission);
    EXPECT_TRUE(m("legacy").two_sided_emission);
    EXPECT_FALSE(m("agreeing").two_sided_emission);
    expect_vec(m("ambient").ambient, {0.1f, 0.2f, 0.3f});
    expect_vec(m("plain").ambient, {0.0f, 0.0f, 0.0f});
    const std::string negative = write_scene("json_scene_negative_ambient", R"({
        "meshes": [{"file": "builtin:triangle"}],
        "materials": {"dark": {"ambient": [0.1, -0.2, 0.3]}}})");
    const std::string message = load_error(negative);
    EXPECT_NE(message.find("materials.dark.ambient"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST(JsonScene, CameraLightsEnvironmentAndRenderSettings) {
    Scene scene = load_scene(json_fixture("scene.json"));
    ASSERT_TRUE(scene.camera.has_value());
    expect_vec(scene.camera->eye, {0, 2, 20});
    expect_vec(scene.camera->target, {0, 1, 0});
    EXPECT_FLOAT_EQ(scene.camera->vfov_degrees, 35.0f);
    EXPECT_FLOAT_EQ(scene.camera->aperture_radius, 0.05f);
    EXPECT_FLOAT_EQ(scene.camera->focus_distance, 19.0f);

    ASSERT_EQ(scene.lights.size(), 3u);
    EXPECT_EQ(scene.lights[0].type, LightType::Point);
    expect_vec(scene.lights[0].position, {0, 8, 0});
    EXPECT_FLOAT_EQ(scene.lights[0].intensity, 50.0f);
    EXPECT_EQ(scene.lights[1].type, LightType::Spot);
    EXPECT_NEAR(scene.lights[1].inner_cone_radians, 10.0f * 3.14159265f / 180.0f, kEps);
    EXPECT_NEAR(scene.lights[1].outer_cone_radians, 30.0f * 3.14159265f / 180.0f, kEps);
    EXPECT_EQ(scene.lights[2].type, LightType::Directional);
    expect_vec(scene.lights[2].direction, {0, -1, 0});  // normalised

    expect_vec(scene.environment.color, {0.1f, 0.2f, 0.3f});
    EXPECT_FLOAT_EQ(scene.environment.strength, 2.0f);
    EXPECT_NEAR(scene.environment.rotation_radians, 3.14159265f / 2.0f, kEps);

    EXPECT_EQ(scene.render_settings.width, 320);
    EXPECT_EQ(scene.render_settings.height, 240);
    EXPECT_EQ(scene.render_settings.spp, 16);
    EXPECT_EQ(scene.render_settings.max_depth, 6);
    EXPECT_EQ(scene.render_settings.integrator, std::string("whitted"));
    ASSERT_TRUE(scene.render_settings.ao_radius.has_value());
    EXPECT_FLOAT_EQ(*scene.render_settings.ao_radius, 0.5f);
}

TEST(JsonScene, PathAndWhittedRenderSettings) {
    const std::string path = write_scene("json_scene_render_settings", R"({
        "meshes": [{"file": "builtin:triangle"}],
        "render": {"integrator": "path", "max_depth": 5, "rr_depth": 2, "light_sampling": "nee",
                   "reflection_depth": 3, "refraction_depth": 4, "shading": "blinn", "update": "two-level"}})");
    const Scene scene = load_scene(path);
    const RenderSettings& r = scene.render_settings;
    EXPECT_EQ(r.integrator, "path");
    EXPECT_EQ(r.max_depth, 5);
    EXPECT_EQ(r.rr_depth, 2);
    EXPECT_EQ(r.light_sampling, "nee");
    EXPECT_EQ(r.reflection_depth, 3);
    EXPECT_EQ(r.refraction_depth, 4);
    EXPECT_EQ(r.shading, "blinn");
    EXPECT_EQ(r.update, "two-level");
}

TEST(JsonScene, LightsAndCameraOfReferencedFilesAreTransformed) {
    const std::string gltf = test::data_path("gltf/hierarchy.gltf");
    const std::string path = write_scene(
        "json_scene_sub_lights",
        R"({"meshes": [{"file": ")" + gltf + R"(", "transform": {"translate": [100, 0, 0]}}]})");
    Scene scene = load_scene(path);
    ASSERT_EQ(scene.lights.size(), 3u);
    expect_vec(scene.lights[0].position, {100, 1, -2});
    ASSERT_TRUE(scene.camera.has_value());  // the JSON has none: the glTF's, moved
    expect_vec(scene.camera->eye, {100, 1, 10});
}

struct JsonErrorCase {
    const char* file;
    const char* fragment;
};

class JsonSceneError : public ::testing::TestWithParam<JsonErrorCase> {};

TEST_P(JsonSceneError, OneLineNamingFileAndPath) {
    const std::string path = json_fixture(GetParam().file);
    const std::string message = load_error(path);
    ASSERT_FALSE(message.empty()) << GetParam().file << " loaded without error";
    EXPECT_EQ(message.rfind(path, 0), 0u) << message;  // starts with the file
    EXPECT_NE(message.find(GetParam().fragment), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

INSTANTIATE_TEST_SUITE_P(
    Malformed, JsonSceneError,
    ::testing::Values(
        JsonErrorCase{"syntax_error.json", ": byte "},
        JsonErrorCase{"unknown_key.json", "meshes[0].transfrom: unknown key"},
        JsonErrorCase{"wrong_type.json", "meshes[1].transform.scale: expected a number or an array of 3 numbers"},
        JsonErrorCase{"missing_mesh.json", "meshes[0].file: "},
        JsonErrorCase{"unknown_material.json", "no material named 'gold'"},
        JsonErrorCase{"self_include.json", "includes itself"}),
    [](const auto& info) { return std::string("case") + std::to_string(info.index); });

TEST(JsonScene, MissingMeshErrorNamesTheMissingFile) {
    const std::string message = load_error(json_fixture("missing_mesh.json"));
    EXPECT_NE(message.find("no_such_mesh.obj"), std::string::npos) << message;
}

TEST(JsonScene, TypeErrorsNameTheirPath) {
    struct Case {
        const char* text;
        const char* fragment;
    };
    const Case cases[] = {
        {R"({"camera": {"fov": "wide"}})", "camera.fov: expected a number"},
        {R"({"lights": [{"type": "laser"}]})", "lights[0].type: expected"},
        {R"({"lights": [{"type": "point", "color": [1, 2]}]})", "lights[0].color: expected an array of 3 numbers"},
        {R"({"render": {"spp": 0}})", "render.spp: expected an integer"},
        {R"({"render": {"width": 1.5}})", "render.width: expected an integer"},
        {R"({"materials": {"m": {"roughness": 2}}})", "materials.m.roughness"},
        {R"({"materials": {"m": {"base_colour": [1, 1, 1]}}})", "materials.m.base_colour: unknown key"},
        {R"({"materials": {"m": {"specular": 1.5}}})", "materials.m.specular: expected a number in [0, 1]"},
        {R"({"materials": {"m": {"specular_color": [1, 2, 0]}}})", "materials.m.specular_color: expected 3 numbers"},
        {R"({"materials": {"m": {"specular_color": 1}}})", "materials.m.specular_color: expected an array"},
        {R"({"materials": {"m": {"two_sided_emission": 1}}})", "materials.m.two_sided_emission: expected true"},
        {R"({"materials": {"m": {"double_sided": "yes"}}})", "materials.m.double_sided: expected true"},
        {R"({"materials": {"m": {"two_sided_emission": true, "double_sided": false}}})",
         "materials.m.double_sided: disagrees with two_sided_emission"},
        {R"({"meshes": {"file": "x.obj"}})", "meshes: expected an array"},
        {R"({"meshes": [{"transform": {}}]})", "meshes[0]: missing \"file\""},
        {R"({"meshes": [{"file": "builtin:triangle", "transform": {"matrix": [1, 2]}}]})",
         "meshes[0].transform.matrix: expected an array of 16 numbers"},
        {R"({"environment": {"strength": -1}})", "environment.strength"},
        {R"({"render": {"integrator": "pathtracer"}})", "render.integrator: unknown value 'pathtracer'"},
        {R"({"render": {"light_sampling": "all"}})", "render.light_sampling: unknown value"},
        {R"({"render": {"shading": "gouraud"}})", "render.shading: unknown value"},
        {R"({"render": {"rr_depth": -1}})", "render.rr_depth: expected an integer"},
        {R"([1, 2, 3])", "top level"},
    };
    int n = 0;
    for (const Case& c : cases) {
        const std::string path = write_scene("json_scene_types_" + std::to_string(n++), c.text);
        const std::string message = load_error(path);
        EXPECT_EQ(message.rfind(path, 0), 0u) << c.text << " -> " << message;
        EXPECT_NE(message.find(c.fragment), std::string::npos) << c.text << " -> " << message;
    }
}

TEST(JsonScene, UnknownExtensionAndMissingFileFromLoadScene) {
    const std::string dir = test::temp_dir("json_scene_dispatch");
    const std::string xyz = dir + "/model.xyz";
    std::ofstream(xyz) << "hello";
    std::string message = load_error(xyz);
    EXPECT_NE(message.find(xyz + ": unsupported scene format '.xyz'"), std::string::npos) << message;
    message = load_error(dir + "/absent.json");
    EXPECT_NE(message.find(dir + "/absent.json"), std::string::npos) << message;
}

}  // namespace
}  // namespace rf
