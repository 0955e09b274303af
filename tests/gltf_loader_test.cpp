// glTF loader: geometry paths (external/embedded buffers, GLB, strides,
// normalized UVs, strips), node transforms, materials and extensions,
// cameras, lights, malformed files, and the real sample scenes when present.
// Fixtures: tests/data/gltf/make_fixtures.py.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

constexpr float kEps = 1e-5f;

void expect_vec(Vec3f actual, Vec3f expected, float eps = kEps) {
    EXPECT_NEAR(actual.x, expected.x, eps);
    EXPECT_NEAR(actual.y, expected.y, eps);
    EXPECT_NEAR(actual.z, expected.z, eps);
}

std::string gltf(const std::string& name) { return test::data_path("gltf/" + name); }

// Loads a malformed file and returns the error message (empty when it loaded).
std::string load_error(const std::string& path) {
    try {
        load_gltf(path);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

TEST(GltfLoader, ExternalBufferIndexedQuadWithNodeTranslation) {
    Scene scene = load_gltf(gltf("quad_external.gltf"));
    ASSERT_EQ(scene.meshes.size(), 1u);
    ASSERT_EQ(scene.instances.size(), 1u);
    EXPECT_EQ(scene.triangle_count(), 2u);
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
    // The file has no normals: they are computed and face +z.
    ASSERT_EQ(mesh.normals.size(), 4u);
    expect_vec(normalize(mesh.normals[0]), {0, 0, 1});
    // One triangle per material id, pointing at the glTF default material.
    ASSERT_EQ(mesh.material_ids.size(), 2u);
    ASSERT_LT(mesh.material_ids[0], scene.materials.size());
    Box3f b = scene.bounds();
    expect_vec(b.lo, {1, 2, 3});
    expect_vec(b.hi, {2, 3, 3});
}

TEST(GltfLoader, LoadsWithoutComputingNormalsWhenAsked) {
    LoadOptions options;
    options.compute_missing_normals = false;
    Scene scene = load_gltf(gltf("quad_external.gltf"), options);
    EXPECT_TRUE(scene.meshes[0].normals.empty());
}

TEST(GltfLoader, EmbeddedBufferStrideNormalizedUvsStripAndSkippedPoints) {
    Scene scene = load_gltf(gltf("embedded.gltf"));
    // Triangle list + strip; the points primitive is skipped.
    ASSERT_EQ(scene.meshes.size(), 2u);
    const Mesh& tri = scene.meshes[0];
    ASSERT_EQ(tri.positions.size(), 3u);
    expect_vec(tri.positions[1], {2, 0, 0});   // read through byteStride 24
    expect_vec(tri.normals[2], {0, 0, 1});     // interleaved at byte 12
    ASSERT_EQ(tri.uvs.size(), 3u);
    EXPECT_NEAR(tri.uvs[1].x, 1.0f, kEps);     // 65535 normalized
    EXPECT_NEAR(tri.uvs[2].y, 1.0f, kEps);
    EXPECT_EQ(tri.indices, (std::vector<uint32_t>{0, 1, 2}));  // non-indexed

    const Mesh& strip = scene.meshes[1];
    ASSERT_EQ(strip.triangle_count(), 2u);
    // Both strip triangles keep the winding (+z normal).
    for (size_t t = 0; t < 2; ++t) {
        Vec3f a = strip.positions[strip.indices[3 * t]], b = strip.positions[strip.indices[3 * t + 1]],
              c = strip.positions[strip.indices[3 * t + 2]];
        EXPECT_GT(cross(b - a, c - a).z, 0.0f) << "strip triangle " << t;
    }
}

TEST(GltfLoader, BinaryGlbWithMatrixNode) {
    Scene scene = load_gltf(gltf("cube.glb"));
    EXPECT_EQ(scene.triangle_count(), 12u);
    Box3f b = scene.bounds();
    expect_vec(b.lo, {-1, -1, -6});
    expect_vec(b.hi, {1, 1, -4});
}

// hierarchy.gltf with the first `from` in its text replaced by `to`.
Scene load_edited_hierarchy(const std::string& test, const std::string& from, const std::string& to) {
    std::ifstream in(gltf("hierarchy.gltf"));
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
    const std::string dir = test::temp_dir(test);
    std::filesystem::copy_file(gltf("checker.png"), dir + "/checker.png");
    std::ofstream(dir + "/edited.gltf") << text;
    return load_gltf(dir + "/edited.gltf");
}

TEST(GltfLoader, KhrMaterialsSpecularFactorsAndSingleSidedEmission) {
    Scene scene = load_edited_hierarchy(
        "gltf_specular", "\"KHR_materials_ior\": {",
        R"("KHR_materials_specular": {"specularFactor": 0.25, "specularColorFactor": [1, 0.5, 0.125],)"
        R"( "specularTexture": {"index": 0}}, "KHR_materials_ior": {)");
    const Material& m = scene.materials[scene.meshes[0].material_ids[0]];
    EXPECT_FLOAT_EQ(m.specular, 0.25f);  // the texture is ignored (warned)
    expect_vec(m.specular_color, {1.0f, 0.5f, 0.125f});

    Scene one_sided = load_edited_hierarchy("gltf_one_sided", "\"doubleSided\": true", "\"doubleSided\": false");
    EXPECT_FALSE(one_sided.materials[one_sided.meshes[0].material_ids[0]].two_sided_emission);
    EXPECT_FLOAT_EQ(one_sided.materials[one_sided.meshes[0].material_ids[0]].specular, 1.0f);  // glTF default
}

TEST(GltfLoader, NodeHierarchyComposesTransforms) {
    Scene scene = load_gltf(gltf("hierarchy.gltf"));
    ASSERT_EQ(scene.instances.size(), 1u);
    // Quad [0,1]^2 scaled by 3, rotated 90 degrees about +y (x -> -z), moved to z = -2.
    Box3f b = scene.bounds();
    expect_vec(b.lo, {0, 0, -5});
    expect_vec(b.hi, {0, 3, -2});
}

TEST(GltfLoader, MaterialFactorsExtensionsAndTextures) {
    Scene scene = load_gltf(gltf("hierarchy.gltf"));
    ASSERT_GE(scene.materials.size(), 1u);
    const Material& m = scene.materials[scene.meshes[0].material_ids[0]];
    EXPECT_EQ(m.name, "fancy");
    expect_vec(m.base_color, {0.5f, 0.25f, 1.0f});
    EXPECT_FLOAT_EQ(m.alpha, 0.75f);
    EXPECT_FLOAT_EQ(m.metallic, 0.2f);
    EXPECT_FLOAT_EQ(m.roughness, 0.7f);
    expect_vec(m.emission, {1.0f, 0.5f, 0.25f});
    EXPECT_FLOAT_EQ(m.emission_strength, 4.0f);
    EXPECT_FLOAT_EQ(m.transmission, 0.9f);
    EXPECT_FLOAT_EQ(m.ior, 1.33f);
    EXPECT_EQ(m.alpha_mode, AlphaMode::Mask);
    EXPECT_FLOAT_EQ(m.alpha_cutoff, 0.3f);
    EXPECT_TRUE(m.two_sided_emission);
    EXPECT_FLOAT_EQ(m.normal_scale, 0.5f);

    // Base color and emission share texture 0 (sRGB); MR and normal use texture 1 (linear).
    ASSERT_NE(m.base_color_texture, kNoTexture);
    EXPECT_EQ(m.base_color_texture, m.emission_texture);
    ASSERT_NE(m.normal_texture, kNoTexture);
    EXPECT_EQ(m.normal_texture, m.metallic_roughness_texture);
    EXPECT_NE(m.normal_texture, m.base_color_texture);
    const Texture& color = scene.textures[size_t(m.base_color_texture)];
    const Texture& data = scene.textures[size_t(m.normal_texture)];
    EXPECT_EQ(color.encoding, TextureEncoding::Srgb8);
    EXPECT_EQ(data.encoding, TextureEncoding::Linear8);
    EXPECT_EQ(color.width, 2);
    EXPECT_EQ(color.height, 2);
    EXPECT_EQ(color.wrap_s, TextureWrap::ClampToEdge);
    EXPECT_EQ(color.wrap_t, TextureWrap::MirroredRepeat);
    EXPECT_EQ(data.wrap_s, TextureWrap::Repeat);  // no sampler
    ASSERT_GE(color.channels, 3);
    EXPECT_EQ(color.texels8[0], 255);  // top-left texel is red
    EXPECT_EQ(color.texels8[1], 0);
}

TEST(GltfLoader, SkipsTexturesWhenAsked) {
    LoadOptions options;
    options.load_textures = false;
    Scene scene = load_gltf(gltf("hierarchy.gltf"), options);
    EXPECT_TRUE(scene.textures.empty());
    EXPECT_EQ(scene.materials[0].base_color_texture, kNoTexture);
}

TEST(GltfLoader, CameraFromFirstCameraNodeOfDefaultScene) {
    Scene scene = load_gltf(gltf("hierarchy.gltf"));
    ASSERT_TRUE(scene.camera.has_value());
    expect_vec(scene.camera->eye, {0, 1, 10});
    expect_vec(normalize(scene.camera->target - scene.camera->eye), {0, 0, -1});
    expect_vec(scene.camera->up, {0, 1, 0});
    EXPECT_NEAR(scene.camera->vfov_degrees, 30.0f, 1e-3f);
}

TEST(GltfLoader, PunctualLightsFollowNodeTransforms) {
    Scene scene = load_gltf(gltf("hierarchy.gltf"));
    ASSERT_EQ(scene.lights.size(), 3u);
    const Light& point = scene.lights[0];
    EXPECT_EQ(point.type, LightType::Point);
    expect_vec(point.position, {0, 1, -2});  // child of the translated root
    expect_vec(point.color, {1, 0.5f, 0.25f});
    EXPECT_FLOAT_EQ(point.intensity, 20.0f);

    const Light& spot = scene.lights[1];
    EXPECT_EQ(spot.type, LightType::Spot);
    expect_vec(spot.position, {0, 4, 0});
    expect_vec(spot.direction, {0, -1, 0});  // -Z rotated -90 degrees about x
    EXPECT_NEAR(spot.inner_cone_radians, 0.1f, kEps);
    EXPECT_NEAR(spot.outer_cone_radians, 0.5f, kEps);

    const Light& sun = scene.lights[2];
    EXPECT_EQ(sun.type, LightType::Directional);
    expect_vec(sun.direction, {0, 0, -1});
    EXPECT_FLOAT_EQ(sun.intensity, 2.0f);
}

TEST(GltfLoader, LoadSceneDispatchesGltfAndGlb) {
    EXPECT_EQ(load_scene(gltf("cube.glb")).triangle_count(), 12u);
    EXPECT_EQ(load_scene(gltf("quad_external.gltf")).triangle_count(), 2u);
}

// Every malformed file gives one line that names the file and the problem.
struct BrokenCase {
    const char* file;
    const char* reason;  // a fragment of the expected message
};

class GltfBrokenFile : public ::testing::TestWithParam<BrokenCase> {};

TEST_P(GltfBrokenFile, FailsWithOneLineNamingTheFile) {
    const BrokenCase& c = GetParam();
    const std::string path = gltf(c.file);
    const std::string message = load_error(path);
    ASSERT_FALSE(message.empty()) << c.file << " loaded without error";
    EXPECT_NE(message.find(path), std::string::npos) << message;
    EXPECT_NE(message.find(c.reason), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

INSTANTIATE_TEST_SUITE_P(
    Malformed, GltfBrokenFile,
    ::testing::Values(BrokenCase{"missing_buffer.gltf", "does_not_exist.bin"},
                      BrokenCase{"accessor_out_of_range.gltf", "exceed its bufferView"},
                      BrokenCase{"view_out_of_range.gltf", "outside its buffer"},
                      BrokenCase{"index_out_of_range.gltf", "out of range"},
                      BrokenCase{"nan_position.gltf", "not finite"},
                      BrokenCase{"node_cycle.gltf", "cycle"},
                      BrokenCase{"syntax_error.gltf", ""},
                      BrokenCase{"no_such_file.gltf", "cannot open"}),
    [](const auto& info) {
        std::string name = info.param.file;
        for (char& ch : name)
            if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
        return name;
    });

// Every prefix of a .glb fails cleanly (an rf::Error naming the file) or loads.
TEST(GltfLoader, TruncatedGlbNeverCrashes) {
    std::ifstream in(gltf("cube.glb"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_GT(bytes.size(), 100u);
    const std::string path = test::temp_dir("gltf_truncated") + "/cut.glb";
    int failures = 0;
    for (size_t length = 0; length < bytes.size(); length += 17) {
        std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes.data(), std::streamsize(length));
        const std::string message = load_error(path);
        if (!message.empty()) {
            ++failures;
            EXPECT_EQ(message.rfind(path, 0), 0u) << message;
            EXPECT_EQ(message.find('\n'), std::string::npos) << message;
        }
    }
    EXPECT_EQ(failures, int((bytes.size() + 16) / 17));  // no prefix is a valid file
}

// The real sample scenes, when ../shared is present. Triangle counts are
// those measured in /work/shared/scenes/MANIFEST.md.
struct SampleScene {
    const char* path;
    size_t triangles;
};

class GltfSampleScene : public ::testing::TestWithParam<SampleScene> {};

TEST_P(GltfSampleScene, LoadsWithManifestTriangleCount) {
    const std::string path = test::shared_path(GetParam().path);
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    Scene scene = load_scene(path);
    EXPECT_EQ(scene.triangle_count(), GetParam().triangles);
    EXPECT_FALSE(scene.textures.empty());
    for (const Mesh& mesh : scene.meshes) EXPECT_EQ(mesh.material_ids.size(), mesh.triangle_count());
}

INSTANTIATE_TEST_SUITE_P(Shared, GltfSampleScene,
                         ::testing::Values(SampleScene{"scenes/gltf-damaged-helmet/DamagedHelmet.gltf", 15452},
                                           SampleScene{"scenes/gltf-box-textured/BoxTextured.gltf", 12},
                                           SampleScene{"scenes/gltf-balloon/scene.gltf", 35698}),
                         [](const auto& info) { return std::string("scene") + std::to_string(info.index); });

}  // namespace
}  // namespace rf
