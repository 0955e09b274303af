// PLY loading: the three encodings of one mesh load equal, unknown elements
// and properties are skipped, and malformed files fail cleanly
// (fixtures: tests/data/ply/make_fixtures.py).
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

std::string ply_fixture(const std::string& name) { return test::data_path("ply/" + name); }

void expect_vec3(Vec3f actual, Vec3f expected) {
    EXPECT_FLOAT_EQ(actual.x, expected.x);
    EXPECT_FLOAT_EQ(actual.y, expected.y);
    EXPECT_FLOAT_EQ(actual.z, expected.z);
}

TEST(PlyLoader, LoadsAsciiPyramid) {
    Scene scene = load_ply(ply_fixture("pyramid_ascii.ply"));
    ASSERT_EQ(scene.meshes.size(), 1u);
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(mesh.vertex_count(), 5u);
    EXPECT_EQ(mesh.triangle_count(), 6u);  // base quad fan-triangulated + 4 sides
    expect_vec3(mesh.positions[4], {0.0f, 1.5f, 0.0f});
    ASSERT_EQ(mesh.normals.size(), 5u);   // taken from the file, not computed
    expect_vec3(mesh.normals[0], {-0.5f, -0.5f, -0.5f});
    ASSERT_EQ(mesh.uvs.size(), 5u);
    EXPECT_FLOAT_EQ(mesh.uvs[4].x, 0.5f);
    EXPECT_FLOAT_EQ(mesh.uvs[4].y, 0.75f);  // v flipped: 0 is the top row
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 4, 1, 1, 4, 2, 2, 4, 3, 3, 4, 0}));
    ASSERT_EQ(scene.materials.size(), 1u);  // the default material: a grey Lambertian
    EXPECT_FLOAT_EQ(scene.materials[0].specular, 0.0f);
    EXPECT_FLOAT_EQ(scene.materials[0].metallic, 0.0f);
    EXPECT_FALSE(scene.materials[0].two_sided_emission);
    EXPECT_EQ(scene.instances.size(), 1u);
    EXPECT_EQ(scene.source, ply_fixture("pyramid_ascii.ply"));
}

TEST(PlyLoader, AllEncodingsLoadEqual) {
    const Mesh reference = load_ply(ply_fixture("pyramid_ascii.ply")).meshes[0];
    for (const char* name : {"pyramid_binary_le.ply", "pyramid_binary_be.ply", "pyramid_crlf_header.ply"}) {
        SCOPED_TRACE(name);
        const Mesh mesh = load_ply(ply_fixture(name)).meshes[0];
        ASSERT_EQ(mesh.vertex_count(), reference.vertex_count());
        for (size_t i = 0; i < mesh.vertex_count(); ++i) {
            EXPECT_TRUE(mesh.positions[i] == reference.positions[i]) << "vertex " << i;
            EXPECT_TRUE(mesh.normals[i] == reference.normals[i]) << "vertex " << i;
            EXPECT_EQ(mesh.uvs[i].x, reference.uvs[i].x);
            EXPECT_EQ(mesh.uvs[i].y, reference.uvs[i].y);
        }
        EXPECT_EQ(mesh.indices, reference.indices);
    }
}

TEST(PlyLoader, ComputesMissingNormalsAndReadsSt) {
    Scene scene = load_ply(ply_fixture("no_normals.ply"));
    const Mesh& mesh = scene.meshes[0];
    EXPECT_EQ(mesh.triangle_count(), 2u);
    ASSERT_EQ(mesh.normals.size(), 4u);
    for (const Vec3f& n : mesh.normals) expect_vec3(n, {0.0f, 0.0f, 1.0f});
    ASSERT_EQ(mesh.uvs.size(), 4u);
    EXPECT_FLOAT_EQ(mesh.uvs[2].x, 1.0f);
    EXPECT_FLOAT_EQ(mesh.uvs[2].y, 0.0f);

    LoadOptions no_normals;
    no_normals.compute_missing_normals = false;
    EXPECT_TRUE(load_ply(ply_fixture("no_normals.ply"), no_normals).meshes[0].normals.empty());
}

struct MalformedPly {
    const char* file;
    const char* fragment;  // expected in the message besides the file name
};

class PlyLoaderMalformed : public ::testing::TestWithParam<MalformedPly> {};

TEST_P(PlyLoaderMalformed, ThrowsOneLineErrorNamingTheFile) {
    const std::string path = ply_fixture(GetParam().file);
    try {
        load_ply(path);
        FAIL() << "no error for " << path;
    } catch (const Error& e) {
        const std::string message = e.what();
        EXPECT_EQ(message.rfind(path, 0), 0u) << message;  // starts with the file
        EXPECT_NE(message.find(GetParam().fragment), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

INSTANTIATE_TEST_SUITE_P(
    Files, PlyLoaderMalformed,
    ::testing::Values(MalformedPly{"truncated_binary.ply", ": byte "},
                      MalformedPly{"truncated_binary.ply", "truncated"},
                      MalformedPly{"truncated_ascii.ply", "truncated"},
                      MalformedPly{"absurd_vertex_count.ply", "header declares 1000000000000 'vertex'"},
                      MalformedPly{"absurd_face_count.ply", "header declares 1000000000000 'face'"},
                      MalformedPly{"huge_list.ply", "truncated"},
                      MalformedPly{"bad_header.ply", ":5: unknown property type 'floot'"},
                      MalformedPly{"no_end_header.ply", "end_header"},
                      MalformedPly{"not_ply.ply", ":1: not a PLY file"},
                      MalformedPly{"out_of_range.ply", ":13: face 0 references vertex 7 of 3"},
                      MalformedPly{"negative_index.ply", "references vertex -1"},
                      MalformedPly{"nan.ply", ":11: vertex 1 has a non-finite coordinate"},
                      MalformedPly{"inf_binary.ply", "vertex 1 has a non-finite coordinate"},
                      MalformedPly{"points_only.ply", "no faces"},
                      MalformedPly{"does_not_exist.ply", "not found"}));

// The 69K-triangle Stanford bunny from ../shared, when present.
TEST(PlyLoader, LoadsStanfordBunny) {
    const std::string path = test::shared_path("scenes/stanford-bunny/bun_zipper.ply");
    if (path.empty()) GTEST_SKIP() << "shared scenes not available";
    Scene scene = load_ply(path);
    EXPECT_EQ(scene.meshes[0].triangle_count(), 69451u);
    EXPECT_EQ(scene.meshes[0].vertex_count(), 35947u);
    EXPECT_EQ(scene.meshes[0].normals.size(), 35947u);  // computed
}

}  // namespace
}  // namespace rf
