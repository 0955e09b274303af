// OBJ + MTL loading: geometry, de-indexing of (v, vt, vn), material mapping,
// texture lookup, and one-line errors for malformed files
// (fixtures: tests/data/obj/make_fixtures.py).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

std::string obj_fixture(const std::string& name) { return test::data_path("obj/" + name); }

void expect_vec3(Vec3f actual, Vec3f expected) {
    EXPECT_FLOAT_EQ(actual.x, expected.x);
    EXPECT_FLOAT_EQ(actual.y, expected.y);
    EXPECT_FLOAT_EQ(actual.z, expected.z);
}

const Material& material_named(const Scene& scene, const std::string& name) {
    auto it = std::find_if(scene.materials.begin(), scene.materials.end(),
                           [&](const Material& m) { return m.name == name; });
    if (it == scene.materials.end()) throw Error("no material " + name);
    return *it;
}

TEST(ObjLoader, LoadsQuadAndComputesNormals) {
    Scene scene = load_obj(obj_fixture("quad.obj"));
    ASSERT_EQ(scene.meshes.size(), 1u);
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(mesh.triangle_count(), 2u);
    EXPECT_EQ(mesh.vertex_count(), 4u);
    expect_vec3(mesh.positions[2], {1.0f, 1.0f, 0.0f});
    ASSERT_EQ(mesh.normals.size(), 4u);
    for (const Vec3f& n : mesh.normals) expect_vec3(n, {0.0f, 0.0f, 1.0f});
    EXPECT_TRUE(mesh.uvs.empty());
    ASSERT_EQ(scene.materials.size(), 1u);
    EXPECT_EQ(scene.materials[0].name, "default");
    EXPECT_EQ(scene.instances.size(), 1u);

    LoadOptions keep;
    keep.compute_missing_normals = false;
    EXPECT_TRUE(load_obj(obj_fixture("quad.obj"), keep).meshes[0].normals.empty());
}

TEST(ObjLoader, LoadsTexturedCubeWithMaterials) {
    Scene scene = load_obj(obj_fixture("cube.obj"));
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(mesh.triangle_count(), 12u);
    EXPECT_EQ(mesh.vertex_count(), 24u);  // 6 faces x 4 distinct (v, vt, vn) corners
    ASSERT_EQ(mesh.normals.size(), 24u);
    ASSERT_EQ(mesh.uvs.size(), 24u);
    // Every vertex keeps its face's normal; the first face faces -z.
    expect_vec3(mesh.normals[mesh.indices[0]], {0.0f, 0.0f, -1.0f});
    // Corner 4/1/1 has vt (0, 0): v is flipped so that 0 is the image's top row.
    EXPECT_FLOAT_EQ(mesh.uvs[mesh.indices[0]].x, 0.0f);
    EXPECT_FLOAT_EQ(mesh.uvs[mesh.indices[0]].y, 1.0f);

    ASSERT_EQ(scene.materials.size(), 2u);
    const Material& checker = material_named(scene, "checker");
    const Material& lamp = material_named(scene, "lamp");
    for (size_t t = 0; t < 12; ++t)
        EXPECT_EQ(scene.materials[mesh.material_ids[t]].name, t < 8 ? "checker" : "lamp") << "triangle " << t;

    // textures\Checker.PNG found as textures/checker.png; map_d merged into its alpha.
    ASSERT_NE(checker.base_color_texture, kNoTexture);
    const Texture& texture = scene.textures[size_t(checker.base_color_texture)];
    EXPECT_EQ(texture.width, 2);
    EXPECT_EQ(texture.channels, 4);
    EXPECT_EQ(texture.encoding, TextureEncoding::Srgb8);
    EXPECT_EQ(texture.texels8, (std::vector<uint8_t>{255, 255, 255, 255, 0, 0, 0, 0,
                                                     0, 0, 0, 255, 255, 255, 255, 0}));
    EXPECT_EQ(checker.alpha_mode, AlphaMode::Mask);
    expect_vec3(checker.base_color, {1.0f, 1.0f, 1.0f});  // the texture carries the color
    EXPECT_FLOAT_EQ(checker.roughness, 1.0f);              // Ks = 0: no highlight

    EXPECT_TRUE(lamp.is_emissive());
    expect_vec3(lamp.emission, {4.0f, 3.0f, 2.0f});
    EXPECT_EQ(lamp.base_color_texture, kNoTexture);
    EXPECT_EQ(scene.textures.size(), 1u);
}

TEST(ObjLoader, SkipsTexturesWhenAsked) {
    LoadOptions options;
    options.load_textures = false;
    Scene scene = load_obj(obj_fixture("cube.obj"), options);
    EXPECT_TRUE(scene.textures.empty());
    EXPECT_EQ(material_named(scene, "checker").base_color_texture, kNoTexture);
    expect_vec3(material_named(scene, "checker").base_color, {0.588f, 0.588f, 0.588f});
}

TEST(ObjLoader, MapsMtlIllumModels) {
    Scene scene = load_obj(obj_fixture("materials.obj"));
    ASSERT_EQ(scene.materials.size(), 5u);

    const Material& mirror = material_named(scene, "mirror");
    EXPECT_FLOAT_EQ(mirror.metallic, 1.0f);
    expect_vec3(mirror.base_color, {0.95f, 0.9f, 0.85f});
    // Walter et al. 2007: Beckmann alpha = sqrt(2 / (Ns + 2)); rf roughness = sqrt(alpha).
    EXPECT_NEAR(mirror.roughness, std::pow(2.0f / 1002.0f, 0.25f), 1e-6f);

    const Material& glass = material_named(scene, "glass");
    EXPECT_FLOAT_EQ(glass.transmission, 1.0f);
    EXPECT_FLOAT_EQ(glass.ior, 1.33f);
    EXPECT_FLOAT_EQ(glass.metallic, 0.0f);
    EXPECT_FLOAT_EQ(glass.roughness, 0.0f);  // MTL refraction is ray traced: smooth
    EXPECT_FLOAT_EQ(glass.specular, 1.0f);   // the interface's Fresnel, not Ks

    const Material& veil = material_named(scene, "veil");
    EXPECT_FLOAT_EQ(veil.alpha, 0.25f);
    EXPECT_EQ(veil.alpha_mode, AlphaMode::Blend);
    EXPECT_FLOAT_EQ(veil.transmission, 0.0f);
    EXPECT_FLOAT_EQ(veil.specular, 0.0f);  // no Ks

    const Material& plastic = material_named(scene, "plastic");
    expect_vec3(plastic.base_color, {0.5f, 0.25f, 0.125f});
    EXPECT_NEAR(plastic.roughness, std::pow(2.0f / 100.0f, 0.25f), 1e-6f);
    EXPECT_FLOAT_EQ(plastic.metallic, 0.0f);
    EXPECT_FLOAT_EQ(plastic.specular, 0.5f);  // Ks 0.5
    expect_vec3(plastic.specular_color, {1.0f, 1.0f, 1.0f});
    EXPECT_FLOAT_EQ(plastic.ior, 1.5f);

    // A usemtl name the library lacks gets a default material of that name.
    const Material& undefined = material_named(scene, "undefined_in_mtl");
    EXPECT_EQ(undefined.base_color_texture, kNoTexture);
    EXPECT_FLOAT_EQ(undefined.specular, 0.0f);  // MTL's defaults have no Ks
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(scene.materials[mesh.material_ids[4]].name, "undefined_in_mtl");
}

// Loads `mtl` through an OBJ that uses every material it names.
Scene load_mtl_text(const std::string& test, const std::string& mtl, const std::vector<std::string>& names) {
    const std::string dir = test::temp_dir(test);
    std::ofstream(dir + "/m.mtl") << mtl;
    std::ofstream obj(dir + "/m.obj");
    obj << "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n";
    for (const std::string& name : names) obj << "usemtl " << name << "\nf 1 2 3\n";
    obj.close();
    return load_obj(dir + "/m.obj");
}

TEST(ObjLoader, MapsKsIllumAndNiByTheMtlSpec) {
    Scene scene = load_mtl_text("obj_mtl_mapping",
                                "newmtl lambert\nKd 0.5 0.5 0.5\nKs 0 0 0\nNs 50\nillum 2\n"
                                "newmtl unlit\nKd 0.5 0.5 0.5\nKs 0.5 0.5 0.5\nillum 0\n"
                                "newmtl diffuse_only\nKd 0.5 0.5 0.5\nKs 0.5 0.5 0.5\nillum 1\n"
                                "newmtl no_illum\nKd 0.5 0.5 0.5\nKs 0.2 0.4 0.1\nNs 10\nNi 1.45\n"
                                "newmtl glass_no_ni\nTf 0.9 1 0.8\nillum 7\n"
                                "newmtl glass_matched\nNi 1.0\nillum 4\n"
                                "newmtl dull_reflector\nKd 0.8 0.8 0.8\nKs 0.3 0.3 0.3\nillum 3\n"
                                "newmtl cutout\nKd 1 0 0\nTr 0.75\n",
                                {"lambert", "unlit", "diffuse_only", "no_illum", "glass_no_ni", "glass_matched",
                                 "dull_reflector", "cutout"});
    EXPECT_FLOAT_EQ(material_named(scene, "lambert").specular, 0.0f);
    EXPECT_FLOAT_EQ(material_named(scene, "unlit").specular, 0.0f);         // illum 0: lit Lambert
    EXPECT_FLOAT_EQ(material_named(scene, "diffuse_only").specular, 0.0f);  // illum 1 ignores Ks

    const Material& coloured = material_named(scene, "no_illum");  // no illum line: as 2
    EXPECT_FLOAT_EQ(coloured.specular, 0.4f);
    expect_vec3(coloured.specular_color, {0.5f, 1.0f, 0.25f});
    EXPECT_FLOAT_EQ(coloured.ior, 1.5f);  // Ni is for refraction only
    EXPECT_FLOAT_EQ(coloured.transmission, 0.0f);

    const Material& glass = material_named(scene, "glass_no_ni");
    EXPECT_FLOAT_EQ(glass.transmission, 1.0f);
    EXPECT_FLOAT_EQ(glass.ior, 1.5f);  // absent Ni (tinyobj reads 1) is not index-matched
    expect_vec3(glass.base_color, {0.9f, 1.0f, 0.8f});  // Tf tints
    EXPECT_FLOAT_EQ(material_named(scene, "glass_matched").ior, 1.0f);

    const Material& dull = material_named(scene, "dull_reflector");  // Ks does not dominate: no metal
    EXPECT_FLOAT_EQ(dull.metallic, 0.0f);
    EXPECT_FLOAT_EQ(dull.specular, 0.3f);

    const Material& cutout = material_named(scene, "cutout");
    EXPECT_FLOAT_EQ(cutout.alpha, 0.25f);
    EXPECT_EQ(cutout.alpha_mode, AlphaMode::Blend);
    EXPECT_FLOAT_EQ(cutout.specular, 0.0f);
}

TEST(ObjLoader, ResolvesNegativeIndicesAndMixedNormals) {
    Scene scene = load_obj(obj_fixture("negative_indices.obj"));
    const Mesh& mesh = scene.meshes[0];
    ASSERT_EQ(mesh.triangle_count(), 3u);
    expect_vec3(mesh.positions[mesh.indices[2]], {1.0f, 1.0f, 0.0f});
    expect_vec3(mesh.positions[mesh.indices[3]], {0.0f, 0.0f, 1.0f});
    expect_vec3(mesh.positions[mesh.indices[8]], {0.0f, 1.0f, 1.0f});
    // The first triangle has file normals, the quad computed ones: both +z here.
    ASSERT_EQ(mesh.normals.size(), mesh.vertex_count());
    for (const Vec3f& n : mesh.normals) expect_vec3(n, {0.0f, 0.0f, 1.0f});
    ASSERT_EQ(scene.materials.size(), 1u);  // no usemtl: one default material
}

TEST(ObjLoader, TriangulatesPolygonsWithCrlfAndTabs) {
    Scene scene = load_obj(obj_fixture("polygon.obj"));
    EXPECT_EQ(scene.meshes[0].triangle_count(), 4u + 3u);
    EXPECT_EQ(scene.meshes[0].vertex_count(), 6u);
}

TEST(ObjLoader, MissingTextureIsOneWarningAndFallsBackToTheFactor) {
    ::testing::internal::CaptureStderr();
    Scene scene = load_obj(obj_fixture("missing_texture.obj"));
    const std::string warnings = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(warnings.find("does_not_exist.png"), std::string::npos) << warnings;
    EXPECT_EQ(std::count(warnings.begin(), warnings.end(), '\n'), 1) << warnings;
    const Material& ghost = material_named(scene, "ghost");
    EXPECT_EQ(ghost.base_color_texture, kNoTexture);
    expect_vec3(ghost.base_color, {0.25f, 0.5f, 0.75f});
    EXPECT_TRUE(scene.textures.empty());
}

struct MalformedObj {
    const char* file;
    const char* fragment;  // expected right after the file name
};

class ObjLoaderMalformed : public ::testing::TestWithParam<MalformedObj> {};

TEST_P(ObjLoaderMalformed, ThrowsOneLineErrorWithFileAndLine) {
    const std::string path = obj_fixture(GetParam().file);
    try {
        load_obj(path);
        FAIL() << "no error for " << path;
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_EQ(message.rfind(path + GetParam().fragment, 0), 0u) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

INSTANTIATE_TEST_SUITE_P(
    Files, ObjLoaderMalformed,
    ::testing::Values(MalformedObj{"out_of_range.obj", ":5: vertex index 9 out of range"},
                      MalformedObj{"negative_out_of_range.obj", ":3: vertex index -3 out of range"},
                      MalformedObj{"zero_index.obj", ":4: vertex index 0"},
                      MalformedObj{"nan.obj", ":2: non-finite number"},
                      MalformedObj{"bad_number.obj", ":3: bad number"},
                      MalformedObj{"bad_face.obj", ":4: bad vertex index"},
                      MalformedObj{"uv_out_of_range.obj", ":5: texture coordinate index 2 out of range"},
                      MalformedObj{"no_faces.obj", ": no faces"},
                      MalformedObj{"does_not_exist.obj", ": file not found"}));

// Shared scenes, when present: Cornell box (emissive light) and Dabrovic
// Sponza (texture names in the wrong letter case).
TEST(ObjLoader, LoadsCornellBox) {
    const std::string path = test::shared_path("scenes/cornell-box/CornellBox-Original.obj");
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    Scene scene = load_obj(path);
    EXPECT_EQ(scene.triangle_count(), 36u);
    EXPECT_TRUE(material_named(scene, "light").is_emissive());
}

TEST(ObjLoader, FindsDabrovicSponzaTexturesIgnoringCase) {
    const std::string path = test::shared_path("scenes/dabrovic-sponza/sponza.obj");
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    ::testing::internal::CaptureStderr();
    Scene scene = load_obj(path);
    const std::string warnings = ::testing::internal::GetCapturedStderr();
    EXPECT_EQ(warnings.find("not found"), std::string::npos) << warnings;
    EXPECT_EQ(scene.triangle_count(), 66450u);
    size_t textured = 0;
    for (const Material& m : scene.materials) textured += m.base_color_texture != kNoTexture;
    EXPECT_GE(textured, 10u);
}

}  // namespace
}  // namespace rf
