// glTF animations (docs/animation.md): the loader's Animation structures for a
// hand-checkable fixture (TRS tracks, a skin, morph targets), the scene after
// Scene::set_time against hand-computed positions, one-line errors for
// malformed animation data, and the generated skinned character.
// Fixture: tests/data/gltf_anim/make_fixture.py (its docstring has the layout).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "io/gltf_loader.h"
#include "io/skinned_character.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "test_paths.h"

namespace rf {
namespace {

constexpr float kEps = 1e-4f;

void expect_vec(Vec3f actual, Vec3f expected, float eps = kEps) {
    EXPECT_NEAR(actual.x, expected.x, eps);
    EXPECT_NEAR(actual.y, expected.y, eps);
    EXPECT_NEAR(actual.z, expected.z, eps);
}

std::string fixture() { return test::data_path("gltf_anim/anim_basic.gltf"); }

int node_named(const Animation& a, const std::string& name) {
    for (size_t i = 0; i < a.nodes.size(); ++i)
        if (a.nodes[i].name == name) return int(i);
    return -1;
}

uint32_t mesh_named(const Scene& scene, const std::string& name) {
    for (uint32_t i = 0; i < scene.meshes.size(); ++i)
        if (scene.meshes[i].name == name) return i;
    ADD_FAILURE() << "no mesh " << name;
    return 0;
}

const Instance& instance_of(const Scene& scene, uint32_t mesh) {
    for (const Instance& inst : scene.instances)
        if (inst.mesh == mesh) return inst;
    ADD_FAILURE() << "no instance of mesh " << mesh;
    return scene.instances.at(0);
}

// World-space vertex v of the (single) instance of `name`.
Vec3f world_vertex(const Scene& scene, const std::string& name, size_t v) {
    const uint32_t mesh = mesh_named(scene, name);
    return instance_of(scene, mesh).transform.transform_point(scene.meshes[mesh].positions.at(v));
}

TEST(GltfAnimation, LoadsNodesAndTracks) {
    const Scene scene = load_gltf(fixture());
    const Animation& a = scene.animation;
    ASSERT_TRUE(scene.animated());
    EXPECT_EQ(a.start, 0.0f);
    EXPECT_EQ(a.end, 2.0f);
    // Only the needed nodes: the animated root, the box under it, the joints.
    EXPECT_EQ(a.nodes.size(), 4u);
    const int root = node_named(a, "root"), box = node_named(a, "box");
    const int joint0 = node_named(a, "joint0"), joint1 = node_named(a, "joint1");
    ASSERT_TRUE(root >= 0 && box >= 0 && joint0 >= 0 && joint1 >= 0);
    EXPECT_EQ(node_named(a, "skinned"), -1);
    EXPECT_EQ(a.nodes[size_t(root)].parent, -1);
    EXPECT_EQ(a.nodes[size_t(box)].parent, root);
    EXPECT_EQ(a.nodes[size_t(joint0)].parent, root);
    EXPECT_EQ(a.nodes[size_t(joint1)].parent, joint0);

    const AnimatedNode& r = a.nodes[size_t(root)];
    expect_vec(r.translation, {1, 0, 0});
    EXPECT_EQ(r.translation_track.interpolation, Interpolation::Linear);
    EXPECT_EQ(r.translation_track.width, 3);
    EXPECT_EQ(r.translation_track.times, (std::vector<float>{0, 2}));
    EXPECT_EQ(r.translation_track.values, (std::vector<float>{1, 0, 0, 3, 0, 0}));
    EXPECT_TRUE(r.rotation_track.empty());

    const AnimatedNode& j1 = a.nodes[size_t(joint1)];
    expect_vec(j1.translation, {0, 1, 0});
    EXPECT_EQ(j1.rotation_track.interpolation, Interpolation::Linear);  // the sampler's default
    EXPECT_EQ(j1.rotation_track.width, 4);
    ASSERT_EQ(j1.rotation_track.values.size(), 8u);
    EXPECT_NEAR(j1.rotation_track.values[6], std::sqrt(0.5f), 1e-6f);
    EXPECT_NEAR(j1.rotation_track.values[7], std::sqrt(0.5f), 1e-6f);

    const AnimatedNode& b = a.nodes[size_t(box)];
    EXPECT_EQ(b.scale_track.interpolation, Interpolation::CubicSpline);
    EXPECT_EQ(b.scale_track.key_count(), 2u);
    EXPECT_EQ(b.scale_track.values.size(), 18u);  // in-tangent, value, out-tangent per key
    EXPECT_EQ(b.scale_track.values[3], 1.0f);
    EXPECT_EQ(b.scale_track.values[12], 2.0f);
}

TEST(GltfAnimation, LoadsInstancesSkinAndMorphs) {
    const Scene scene = load_gltf(fixture());
    const Animation& a = scene.animation;
    ASSERT_EQ(scene.instances.size(), 3u);
    // The box (under the animated root) is linked to its node; the skinned
    // mesh sits at the identity; the morphed one keeps its static transform.
    ASSERT_EQ(a.instances.size(), 1u);
    const uint32_t box = mesh_named(scene, "box"), skinned = mesh_named(scene, "skinned");
    const uint32_t morphed = mesh_named(scene, "morphed");
    EXPECT_EQ(scene.instances[a.instances[0].instance].mesh, box);
    EXPECT_EQ(a.nodes[a.instances[0].node].name, "box");
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 4; ++c) {
            EXPECT_EQ(a.instances[0].local.m[r][c], Affine3f::identity().m[r][c]);
            EXPECT_EQ(instance_of(scene, skinned).transform.m[r][c], Affine3f::identity().m[r][c]);
        }
    expect_vec(instance_of(scene, morphed).transform.transform_point(Vec3f(0.0f)), {0, 0, -2});

    ASSERT_EQ(a.skins.size(), 1u);
    const Skin& skin = a.skins[0];
    EXPECT_EQ(skin.mesh, skinned);
    ASSERT_EQ(skin.joints.size(), 2u);
    EXPECT_EQ(a.nodes[skin.joints[0]].name, "joint0");
    EXPECT_EQ(a.nodes[skin.joints[1]].name, "joint1");
    ASSERT_EQ(skin.inverse_bind.size(), 2u);
    expect_vec(skin.inverse_bind[0].transform_point(Vec3f(0.0f)), {-1, 0, 0});
    expect_vec(skin.inverse_bind[1].transform_point(Vec3f(0.0f)), {-1, -1, 0});
    ASSERT_EQ(skin.vertex_joints.size(), 3u);
    EXPECT_EQ(skin.vertex_joints[0][0], 0);
    EXPECT_EQ(skin.vertex_joints[1][0], 1);
    EXPECT_EQ(skin.vertex_joints[2][0], 0);
    EXPECT_EQ(skin.vertex_joints[2][1], 1);
    EXPECT_EQ(skin.vertex_weights[0].x, 1.0f);
    EXPECT_EQ(skin.vertex_weights[1].x, 1.0f);
    EXPECT_EQ(skin.vertex_weights[2].x, 0.5f);  // 255/255 + 255/255, renormalised
    EXPECT_EQ(skin.vertex_weights[2].y, 0.5f);
    EXPECT_EQ(skin.vertex_weights[2].z + skin.vertex_weights[2].w, 0.0f);

    ASSERT_EQ(a.morphs.size(), 1u);
    const MorphTargets& m = a.morphs[0];
    EXPECT_EQ(m.mesh, morphed);
    ASSERT_EQ(m.position_deltas.size(), 2u);
    expect_vec(m.position_deltas[0][0], {0, 0, 1});
    expect_vec(m.position_deltas[1][1], {0, 0, 2});
    expect_vec(m.position_deltas[1][0], {0, 0, 0});
    EXPECT_TRUE(m.normal_deltas.empty());
    EXPECT_EQ(m.default_weights, (std::vector<float>{0.5f, 0.5f}));
    EXPECT_EQ(m.weights.interpolation, Interpolation::Step);
    EXPECT_EQ(m.weights.width, 2);
    EXPECT_EQ(m.weights.values, (std::vector<float>{0, 0.5f, 1, 0.25f}));
}

// The fixture's world-space vertices at time t, by hand (see make_fixture.py).
struct Expected {
    Vec3f skinned[3], box[3], morphed[3];
};
Expected expected_at(float t) {
    const float tc = std::clamp(t, 0.0f, 2.0f), u = std::clamp(t, 0.0f, 1.0f);
    const float x = 1.0f + tc;                      // root translation
    const float theta = 0.5f * 3.14159265f * u;     // joint1 rotation about z
    const float s = 1.0f + (3 * u * u - 2 * u * u * u);  // Hermite, zero tangents, 1 -> 2
    const float w0 = t < 1.0f ? 0.0f : 1.0f, w1 = t < 1.0f ? 0.5f : 0.25f;  // STEP weights
    const float c = std::cos(theta), sn = std::sin(theta);
    Expected e;
    e.skinned[0] = {x, 0, 0};
    e.skinned[1] = {x - sn, 1 + c, 0};
    e.skinned[2] = {0.5f * ((x + 1) + (x + c)), 0.5f * (1 + (1 + sn)), 0};
    e.box[0] = {x, 0, 0};
    e.box[1] = {x + s, 0, 0};
    e.box[2] = {x, s, 0};
    e.morphed[0] = {0, 0, -2 + w0};
    e.morphed[1] = {1, 0, -2 + 2 * w1};
    e.morphed[2] = {0, 1, -2};
    return e;
}

void expect_fixture_at(const Scene& scene, float t) {
    SCOPED_TRACE("t = " + std::to_string(t));
    const Expected e = expected_at(t);
    for (size_t v = 0; v < 3; ++v) {
        expect_vec(world_vertex(scene, "skinned", v), e.skinned[v]);
        expect_vec(world_vertex(scene, "box", v), e.box[v]);
        expect_vec(world_vertex(scene, "morphed", v), e.morphed[v]);
    }
}

TEST(GltfAnimation, SetTimeMatchesHandComputedSkinningAndMorphs) {
    Scene scene = load_gltf(fixture());
    expect_fixture_at(scene, 0.0f);  // loaded scenes are evaluated at the start
    // Forwards, past the end (held), then backwards.
    for (float t : {0.25f, 0.5f, 1.0f, 1.5f, 2.0f, 3.0f, 1.25f, 0.75f, 0.0f}) {
        const GeometryChange change = scene.set_time(t);
        expect_fixture_at(scene, t);
        (void)change;
    }
}

TEST(GltfAnimation, SetTimeReportsTheDeformedMeshes) {
    Scene scene = load_gltf(fixture());
    const GeometryChange change = scene.set_time(0.5f);
    const uint32_t skinned = mesh_named(scene, "skinned"), morphed = mesh_named(scene, "morphed");
    EXPECT_TRUE(std::find(change.meshes.begin(), change.meshes.end(), skinned) != change.meshes.end());
    EXPECT_TRUE(std::find(change.meshes.begin(), change.meshes.end(), morphed) == change.meshes.end())
        << "a STEP weight does not change between t = 0 and 0.5";
    EXPECT_FALSE(change.instances.empty());
}

// --- Malformed animation data -------------------------------------------------

nlohmann::json fixture_json() {
    std::ifstream in(fixture());
    return nlohmann::json::parse(in);
}

// The fixture after `mutate`, written as NAME.gltf in a fresh directory.
std::string write_mutated(const std::string& name, const std::function<void(nlohmann::json&)>& mutate) {
    nlohmann::json doc = fixture_json();
    mutate(doc);
    const std::string path = test::temp_dir("gltf_anim_" + name) + "/" + name + ".gltf";
    std::ofstream(path) << doc.dump();
    return path;
}

// The error loading the fixture after `mutate`, "" when it loads.
std::string error_after(const std::string& name, const std::function<void(nlohmann::json&)>& mutate) {
    const std::string path = write_mutated(name, mutate);
    try {
        load_gltf(path);
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

void expect_error(const std::string& name, const std::function<void(nlohmann::json&)>& mutate,
                  const std::string& expected) {
    const std::string message = error_after(name, mutate);
    EXPECT_NE(message.find(expected), std::string::npos) << name << ": " << message;
    EXPECT_NE(message.find(name + ".gltf"), std::string::npos) << message;
    EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

TEST(GltfAnimation, MalformedSamplersGiveOneLineErrors) {
    expect_error("short_output", [](auto& d) { d["accessors"][11]["count"] = 1; }, "holds 3 floats, expected 6");
    expect_error("decreasing_times", [](auto& d) { d["animations"][0]["samplers"][0]["input"] = 15; },
                 "not strictly increasing");
    expect_error("interpolation", [](auto& d) { d["animations"][0]["samplers"][0]["interpolation"] = "BEZIER"; },
                 "unknown interpolation 'BEZIER'");
    expect_error("integer_input", [](auto& d) { d["animations"][0]["samplers"][1]["input"] = 3; },
                 "must hold float scalars");
    expect_error("missing_sampler", [](auto& d) { d["animations"][0]["channels"][0]["sampler"] = 9; },
                 "sampler 9 does not exist");
    expect_error("missing_node", [](auto& d) { d["animations"][0]["channels"][0]["target"]["node"] = 99; },
                 "node 99 does not exist");
    expect_error("twice", [](auto& d) { d["animations"][0]["channels"].push_back(d["animations"][0]["channels"][0]); },
                 "animated twice");
    expect_error("weights_without_targets",
                 [](auto& d) { d["animations"][0]["channels"][3]["target"]["node"] = 3; }, "has no morph targets");
    expect_error("animated_matrix", [](auto& d) {
        d["nodes"][0].erase("translation");
        d["nodes"][0]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1, 0, 0, 1};
    }, "has a matrix");
    // Normalized shorts are valid rotations; these bytes make key 0 a zero quaternion.
    expect_error("short_rotation", [](auto& d) {
        d["accessors"][12]["componentType"] = 5122;
        d["accessors"][12]["normalized"] = true;
    }, "rotation key 0 is a zero quaternion");
    expect_error("short_translation", [](auto& d) {
        d["accessors"][11]["componentType"] = 5122;
        d["accessors"][11]["normalized"] = true;
    }, "unsupported component type");
    expect_error("rotation_as_vec3", [](auto& d) { d["animations"][0]["samplers"][1]["output"] = 11; },
                 "unexpected element type");
}

TEST(GltfAnimation, MalformedSkinsAndMorphsGiveOneLineErrors) {
    expect_error("joint_range", [](auto& d) { d["skins"][0]["joints"] = {1}; }, "joint 1 is out of range (1 joints)");
    expect_error("weights_count", [](auto& d) { d["accessors"][2]["count"] = 2; }, "count differs from POSITION count");
    expect_error("float_joints", [](auto& d) { d["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"] = 0; },
                 "must be unsigned byte or short VEC4");
    expect_error("no_weights", [](auto& d) { d["meshes"][0]["primitives"][0]["attributes"].erase("WEIGHTS_0"); },
                 "JOINTS_0 and WEIGHTS_0 must come together");
    expect_error("inverse_binds", [](auto& d) { d["accessors"][8]["count"] = 1; }, "1 matrices for 2 joints");
    expect_error("joint_node", [](auto& d) { d["skins"][0]["joints"] = {1, 42}; }, "joint node 42 does not exist");
    expect_error("default_weights", [](auto& d) { d["meshes"][2]["weights"] = {1}; },
                 "1 default weights for 2 morph targets");
    expect_error("target_count", [](auto& d) { d["accessors"][6]["count"] = 2; }, "count differs from POSITION count");
}

// LoadOptions::animation picks the clip by name or index; the scene keeps
// every clip's name; a clip the file lacks is a one-line error naming the
// file's clips (and so is any clip asked of a file without animations).
TEST(GltfAnimation, ClipChosenByNameOrIndex) {
    const std::string path = write_mutated("two_clips", [](auto& d) {
        d["animations"][0]["name"] = "full";
        nlohmann::json second = d["animations"][0];
        second["name"] = "first channel";
        second["channels"] = nlohmann::json::array({d["animations"][0]["channels"][0]});
        d["animations"].push_back(second);
    });
    const Scene first = load_gltf(path);
    EXPECT_EQ(first.animation.clip, "full");
    EXPECT_EQ(first.animation.clips, std::vector<std::string>({"full", "first channel"}));
    LoadOptions by_name;
    by_name.animation = "first channel";
    const Scene second = load_gltf(path, by_name);
    EXPECT_EQ(second.animation.clip, "first channel");
    LoadOptions by_index;
    by_index.animation = "1";
    const Scene also_second = load_gltf(path, by_index);
    EXPECT_EQ(also_second.animation.clip, "first channel");
    // One channel animates less than the whole clip.
    size_t full_tracks = 0, one_tracks = 0;
    for (const AnimatedNode& n : first.animation.nodes)
        full_tracks += !n.translation_track.empty() + !n.rotation_track.empty() + !n.scale_track.empty();
    for (const AnimatedNode& n : second.animation.nodes)
        one_tracks += !n.translation_track.empty() + !n.rotation_track.empty() + !n.scale_track.empty();
    EXPECT_LT(one_tracks, full_tracks);
    for (const char* wanted : {"nope", "2"}) {
        LoadOptions missing;
        missing.animation = wanted;
        try {
            (void)load_gltf(path, missing);
            ADD_FAILURE() << wanted << " loaded";
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_NE(what.find("no animation '" + std::string(wanted) + "' (the file has 0 'full', 1 'first channel')"),
                      std::string::npos) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        }
    }
}

TEST(GltfAnimation, FileWithoutAnimationsStaysStill) {
    const std::string path = write_mutated("still", [](auto& d) {
        d.erase("animations");
        d["nodes"][4].erase("skin");
        d["meshes"][0]["primitives"][0]["attributes"].erase("JOINTS_0");
        d["meshes"][0]["primitives"][0]["attributes"].erase("WEIGHTS_0");
        d["meshes"][2].erase("weights");
        d["meshes"][2]["primitives"][0].erase("targets");
    });
    const Scene scene = load_gltf(path);
    EXPECT_FALSE(scene.animated());
    EXPECT_TRUE(scene.animation.nodes.empty());
    EXPECT_EQ(scene.animation.start, scene.animation.end);
}

// Random changes to the embedded buffer (key times, values, joints, weights,
// deltas, indices): each file loads and evaluates, or fails with one line.
TEST(GltfAnimation, MutatedBuffersLoadOrFailCleanly) {
    std::ifstream in(fixture());
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const size_t begin = text.find("base64,") + 7, end = text.find('"', begin);
    ASSERT_LT(begin, end);
    const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const std::string dir = test::temp_dir("gltf_anim_mutated");
    uint64_t state = 2101;
    auto next = [&state](uint64_t n) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return (state >> 33) % n;
    };
    int loaded = 0, failed = 0;
    for (int round = 0; round < 200; ++round) {
        std::string mutated = text;
        for (uint64_t k = 0, n = 1 + next(6); k < n; ++k)
            mutated[begin + next(end - begin)] = alphabet[next(alphabet.size())];
        const std::string path = dir + "/m" + std::to_string(round) + ".gltf";
        std::ofstream(path) << mutated;
        try {
            Scene scene = load_gltf(path);
            for (float t : {-1.0f, 0.3f, 1.0f, 5.0f, 0.0f}) (void)scene.set_time(t);
            ++loaded;
        } catch (const Error& e) {
            EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
            ++failed;
        }
    }
    EXPECT_GT(loaded, 0);
    EXPECT_GT(failed, 0);
}

// --- The generated character ----------------------------------------------------

TEST(SkinnedCharacter, IsDeterministicAndLoadsBack) {
    io::SkinnedCharacterOptions small;
    small.slices = 12;
    small.rings_per_meter = 30;
    const std::string text = io::make_skinned_character(small);
    EXPECT_EQ(text, io::make_skinned_character(small));
    const Scene scene = io::load_gltf_text(text, "character.gltf");
    ASSERT_EQ(scene.animation.skins.size(), 1u);
    EXPECT_GE(scene.animation.skins[0].joints.size(), 6u);
    EXPECT_EQ(scene.animation.morphs.size(), 1u);
    EXPECT_EQ(scene.animation.start, 0.0f);
    EXPECT_EQ(scene.animation.end, 2.0f);
    EXPECT_TRUE(scene.camera.has_value());
    for (const Vec4f& w : scene.animation.skins[0].vertex_weights) EXPECT_NEAR(w.x + w.y + w.z + w.w, 1.0f, 1e-6f);
    EXPECT_THROW(io::make_skinned_character({.slices = 2}), Error);
}

// The default character: within the triangle range, walking in place without
// tearing (smooth weights keep every edge short) and standing on the ground.
TEST(SkinnedCharacter, WalksWithoutTearing) {
    Scene scene = io::make_skinned_character_scene();
    EXPECT_EQ(scene.source, "builtin:skinned");
    const uint32_t body = mesh_named(scene, "character");
    const size_t triangles = scene.meshes[body].triangle_count();
    EXPECT_GE(triangles, 3000u);
    EXPECT_LE(triangles, 50000u);
    const std::vector<Vec3f> start = scene.meshes[body].positions;
    for (float t : {0.0f, 0.3f, 0.5f, 1.0f, 1.7f}) {
        scene.set_time(t);
        const Mesh& mesh = scene.meshes[body];
        Box3f bounds;
        for (Vec3f p : mesh.positions) bounds.extend(p);
        EXPECT_GT(bounds.lo.y, -0.05f) << t;
        EXPECT_LT(bounds.lo.y, 0.2f) << t;
        EXPECT_GT(bounds.hi.y, 1.8f) << t;
        EXPECT_LT(bounds.hi.y, 2.0f) << t;
        float longest = 0.0f;
        for (size_t i = 0; i < mesh.indices.size(); i += 3)
            for (int k = 0; k < 3; ++k)
                longest = std::max(longest, length(mesh.positions[mesh.indices[i + size_t(k)]] -
                                                   mesh.positions[mesh.indices[i + size_t(k + 1) % 3]]));
        EXPECT_LT(longest, 0.25f) << t;
    }
    scene.set_time(0.5f);
    EXPECT_NE(scene.meshes[body].positions, start);  // it moves
}

}  // namespace
}  // namespace rf
