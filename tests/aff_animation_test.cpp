// BART AFF animations kept in Scene::animation (src/io/aff/aff_animation.cpp):
// load_aff + Scene::set_time(t) against the still scene load_aff_at_time(t)
// builds (hidden blocks left out) on the fixtures, on a nested file written
// here, and on the BART scenes of ../shared when present; the mapping
// (nodes, keyframes, camera, time range); malformed animation blocks.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "scene_load_error.h"
#include "test_paths.h"

namespace rf {
namespace {

namespace fs = std::filesystem;

std::string aff_fixture(const std::string& name) { return test::data_path("aff/" + name); }

// World-space corners and normals of the visible instances, in order, then the camera.
std::vector<float> flatten(const Scene& s) {
    std::vector<float> out;
    auto push = [&](Vec3f v) { out.insert(out.end(), {v.x, v.y, v.z}); };
    for (const Instance& inst : s.instances) {
        if (!inst.visible) continue;
        const Mesh& m = s.meshes[inst.mesh];
        for (uint32_t i : m.indices) push(inst.transform.transform_point(m.positions[i]));
        for (uint32_t i : m.indices) push(m.normals[i]);
    }
    const Camera c = s.camera_or_default();
    push(c.eye), push(c.target), push(c.up);
    out.push_back(c.vfov_degrees);
    return out;
}

void expect_same_scene(const Scene& animated, const Scene& still, float t) {
    SCOPED_TRACE("time " + std::to_string(t));
    const std::vector<float> a = flatten(animated), b = flatten(still);
    ASSERT_EQ(a.size(), b.size());
    size_t bad = 0, first_bad = 0;
    for (size_t i = 0; i < a.size(); ++i) {
        if (std::fabs(a[i] - b[i]) <= 2e-5f * std::max(1.0f, std::fabs(b[i]))) continue;
        if (bad++ == 0) first_bad = i;
    }
    EXPECT_EQ(bad, 0u) << "first at float " << first_bad << ": " << a[first_bad] << " vs " << b[first_bad];
}

// set_time at each time (in the given order, backwards too) against a still load at that time.
void expect_matches_still(const std::string& path, const std::vector<float>& times) {
    Scene animated = load_aff(path);
    ASSERT_TRUE(animated.animated());
    animated.finalize();
    for (float t : times) {
        animated.set_time(t);
        expect_same_scene(animated, load_aff_at_time(path, t), t);
    }
}

TEST(AffAnimation, FixtureMatchesStillLoadsAtSeveralTimes) {
    expect_matches_still(aff_fixture("animated.aff"), {1.0f, 1.5f, 2.0f, 2.7f, 5.0f, -10.0f, 1.25f});
}

TEST(AffAnimation, FixtureMapping) {
    Scene s = load_scene(aff_fixture("animated.aff"));
    const Animation& a = s.animation;
    EXPECT_FLOAT_EQ(a.start, 1.0f);  // 'a 1 3 10'
    EXPECT_FLOAT_EQ(a.end, 3.0f);
    EXPECT_EQ(a.frame_count(), 10);
    EXPECT_FLOAT_EQ(s.time, 1.0f);
    ASSERT_EQ(a.nodes.size(), 4u);  // mover, hider, unanimated, camera
    EXPECT_EQ(a.nodes[0].name, "mover");
    EXPECT_EQ(a.nodes[0].translation_track.interpolation, Interpolation::KochanekBartels);
    EXPECT_EQ(a.nodes[0].translation_track.key_count(), 4u);
    EXPECT_EQ(a.nodes[1].visibility.interpolation, Interpolation::Step);
    EXPECT_EQ(a.instances.size(), 3u);
    ASSERT_EQ(a.vertex_keyframes.size(), 1u);
    EXPECT_EQ(a.vertex_keyframes[0].times, std::vector<float>({0.0f, 2.0f}));
    ASSERT_TRUE(a.camera.has_value());
    EXPECT_EQ(a.camera->node, 3);
    // The first set_time after loading reports everything animated; the hider is kept, hidden.
    const size_t triangles = s.triangle_count();
    GeometryChange c = s.set_time(2.0f);
    EXPECT_EQ(c.instances.size(), 4u);  // mover, hider, unanimated, the root's loose mesh (tpa)
    EXPECT_EQ(c.meshes.size(), 1u);
    EXPECT_TRUE(c.camera);
    EXPECT_EQ(s.triangle_count(), triangles);
    EXPECT_EQ(std::count_if(s.instances.begin(), s.instances.end(), [](const Instance& i) { return !i.visible; }), 1);
    EXPECT_FALSE(s.set_time(2.5f).geometry());  // the tpa keys end at 2, and so do the splines' inner keys
    c = s.set_time(1.25f);
    EXPECT_EQ(c.meshes.size(), 1u);
    EXPECT_EQ(c.instances.size(), 3u);  // the mover, the hider shown again, the tpa's mesh; not the unanimated block
}

// Nested animated blocks with a static block between them, rotation keys
// across hemispheres, repeated key times, a hidden parent, and the camera's
// transl keys without rot.
constexpr const char* kNested = R"(a 0 4 5
v from 0 0 10 at 0 0 0 up 0 1 0 angle 40 resolution 8 8
x outer {
  p 3  0 0 0  1 0 0  0 1 0
  xs 1 2 1  0 0 1 30  1 0 0 {
    x inner {
      pp 3  0 0 0 0 0 1  1 0 0 0 0 1  0 1 0 0 1 1
    }
  }
}
xs 1 1 1  0 1 0 0  0 5 0 {
  p 3  0 0 0  2 0 0  0 2 0
}
k outer {
  rot 6
    0 0 0 1 0  0 0 0
    0 0 0 1 0  0 0 0
    1 0 0 1 170  0 0 0
    2 0 0 1 350  0.5 0 0
    3 0 0 1 400  0 0.5 0
    4 0 0 1 400  0 0 0.5
  visibility 3  1 1  2.5 0  3.5 1
}
k inner {
  transl 5  0 0 0 0  0 0 0  0 0 0 0  0 0 0  1 1 2 3  0 0 0  3 2 0 0  0 0 0  3 2 0 0  0 0 0
  scale 4  0 1 1 1  0 0 0  1 1 1 1  0 0 0  2 2 3 4  0 0 0  4 2 3 4  0 0 0
}
k camera {
  transl 4  0 0 0 10  0 0 0  1 0 0 10  0 0 0  2 1 1 12  0 0 0  3 1 1 12  0 0 0
}
)";

TEST(AffAnimation, NestedBlocksMatchStillLoads) {
    const std::string dir = test::temp_dir("aff_animation_nested");
    const std::string path = dir + "/nested.aff";
    std::ofstream(path) << kNested;
    expect_matches_still(path, {0.0f, 0.5f, 1.3f, 2.0f, 2.6f, 3.7f, 4.0f, 1.1f, 0.2f});
    Scene s = load_aff(path);
    EXPECT_EQ(s.animation.nodes.size(), 4u);  // outer, the static block under it, inner, camera
    EXPECT_EQ(s.animation.nodes[2].parent, 1);
    EXPECT_FLOAT_EQ(s.animation.frames_per_second, 1.0f);  // 5 frames over 4 s, both ends included
    s.set_time(3.0f);
    EXPECT_EQ(std::count_if(s.instances.begin(), s.instances.end(), [](const Instance& i) { return !i.visible; }), 2);
}

TEST(AffAnimation, MalformedAnimationBlocksFailWithFileAndLine) {
    const std::string dir = test::temp_dir("aff_animation_bad");
    struct Case {
        const char* text;
        const char* expected;
    };
    const Case cases[] = {
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n visibility 2 2 1\n 1 0 }\n", "bad.aff:4: visibility times must not decrease"},
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n visibility 1 1 2 }\n", "bad.aff:3: visibility flag must be 0 or 1"},
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n rot 3 0 0 0 1 0 0 0 0 1 0 0 1 0 0 0 0 2 0 0 1 0 0 0 0 }\n", "needs at least 4 keyframes"},
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n transl 4 0 0 0 nan 0 0 0\n", "bad.aff:3"},
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n wiggle 1 0 }\n", "unknown keyframe type 'wiggle'"},
        {"p 3 0 0 0 1 0 0 0 1 0\nk a {\n transl 4 0 0 0 0 0 0 0 1 0 0 0 0 0 0 2 0 0 0 0 0 0 3 0 0 0 0 0 0\n", "bad.aff"},
        {"x a {\n p 3 0 0 0 1 0 0 0 1 0\n}\nk a {\n scale 4 0 1 1 1 0 0 0 1 0 0 0 0 0 0 2 1 1 1 0 0 0 3 1 1 1 0 0 0 }\n",
         "bad.aff:1: transform is singular"},
    };
    for (const Case& c : cases) {
        const std::string path = dir + "/bad.aff";
        std::ofstream(path) << c.text;
        const std::string message = test::load_error(path);
        SCOPED_TRACE(c.text);
        EXPECT_NE(message.find(c.expected), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

// The BART scenes of ../shared: two times each besides the start, one of them backwards.
TEST(AffAnimation, SharedBartScenesMatchStillLoads) {
    struct SharedScene {
        const char* path;
        std::vector<float> times;
    };
    const SharedScene scenes[] = {
        {"scenes/bart-kitchen/aff/kitchen.aff", {0.0f, 13.7f, 3.3f}},
        {"scenes/bart-robot/aff/Robot.aff", {0.0f, 31.1f, 12.3f}},
        {"scenes/bart-museum/aff/museum5.aff", {-1.0f, 3.6f, 0.55f}},
    };
    bool any = false;
    for (const SharedScene& s : scenes) {
        const std::string path = test::shared_path(s.path);
        if (path.empty()) continue;
        any = true;
        SCOPED_TRACE(s.path);
        expect_matches_still(path, s.times);
    }
    if (!any) GTEST_SKIP() << "../shared/scenes/bart-* not present";
}

}  // namespace
}  // namespace rf
