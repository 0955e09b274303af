// Animation evaluation (src/scene/animation.cpp): each interpolation against
// hand-computed values, Scene::set_time on a small hierarchy, what
// GeometryChange reports, morphs and skins, and the one-line errors of
// Scene::finalize for malformed animation data.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "rayforge/core/error.h"
#include "rayforge/scene/scene.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {
namespace {

constexpr float kPi = 3.14159265358979f;

Track make_track(Interpolation interp, int width, std::vector<float> times, std::vector<float> values) {
    Track t;
    t.interpolation = interp;
    t.width = width;
    t.times = std::move(times);
    t.values = std::move(values);
    if (interp == Interpolation::KochanekBartels) t.tcb.assign(t.times.size(), Vec3f{0, 0, 0});
    return t;
}

std::vector<float> eval(const Track& t, float time) {
    std::vector<float> out(size_t(t.width));
    evaluate_track(t, time, out.data());
    return out;
}

void expect_values(const std::vector<float>& got, const std::vector<float>& want, float tol = 1e-5f) {
    ASSERT_EQ(got.size(), want.size());
    for (size_t i = 0; i < got.size(); ++i) EXPECT_NEAR(got[i], want[i], tol) << "component " << i;
}

std::vector<float> quat_z(float degrees) {  // x, y, z, w about +z
    const float h = degrees * kPi / 360.0f;
    return {0, 0, std::sin(h), std::cos(h)};
}

TEST(Animation, StepHoldsThePreviousKeyAndClamps) {
    const Track t = make_track(Interpolation::Step, 1, {0, 1, 2}, {0, 10, 20});
    expect_values(eval(t, -1.0f), {0});
    expect_values(eval(t, 0.99f), {0});
    expect_values(eval(t, 1.0f), {10});
    expect_values(eval(t, 1.5f), {10});
    expect_values(eval(t, 9.0f), {20});
}

TEST(Animation, LinearLerpsAndSlerps) {
    const Track t = make_track(Interpolation::Linear, 3, {0, 2}, {0, 0, 0, 2, 4, 6});
    expect_values(eval(t, 0.5f), {0.5f, 1.0f, 1.5f});
    expect_values(eval(t, -3.0f), {0, 0, 0});
    expect_values(eval(t, 3.0f), {2, 4, 6});
    std::vector<float> q = quat_z(0), q90 = quat_z(90);
    Track r = make_track(Interpolation::Linear, 4, {0, 1}, {});
    r.values = q;
    r.values.insert(r.values.end(), q90.begin(), q90.end());
    expect_values(eval(r, 0.5f), quat_z(45));
    expect_values(eval(r, 0.25f), quat_z(22.5f));
    for (int c = 4; c < 8; ++c) r.values[size_t(c)] = -r.values[size_t(c)];  // the same rotation: still the short way
    expect_values(eval(r, 0.5f), quat_z(45));
}

TEST(Animation, CubicSplineFollowsGltfHermite) {
    // Keys (in, value, out): t=0 (_, 1, 0.5), t=2 (-1, 3, _). At t=1 (s=0.5, interval 2):
    // 0.5*1 + 0.125*2*0.5 + 0.5*3 + (-0.125)*2*(-1) = 2.375.
    const Track t = make_track(Interpolation::CubicSpline, 1, {0, 2}, {9, 1, 0.5f, -1, 3, 9});
    expect_values(eval(t, 1.0f), {2.375f});
    expect_values(eval(t, 0.0f), {1});
    expect_values(eval(t, 5.0f), {3});
    // Quaternions come back normalised: halfway between identity and 90 degrees with zero tangents.
    Track r = make_track(Interpolation::CubicSpline, 4, {0, 1}, {});
    const std::vector<float> zero(4, 0.0f), a = quat_z(0), b = quat_z(90);
    for (const auto* part : {&zero, &a, &zero, &zero, &b, &zero}) r.values.insert(r.values.end(), part->begin(), part->end());
    const std::vector<float> q = eval(r, 0.5f);
    EXPECT_NEAR(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3], 1.0f, 1e-5f);
    expect_values(q, quat_z(45));  // symmetric Hermite: the normalised midpoint
}

TEST(Animation, KochanekBartelsMatchesBart) {
    // Zero tension/continuity/bias on uniform keys is Catmull-Rom: 6.1875 at 1.5.
    Track t = make_track(Interpolation::KochanekBartels, 3, {0, 1, 2, 3}, {0, 1, 0, 5, 1, 0, 7, 1, 0, 9, 1, 0});
    expect_values(eval(t, 1.5f), {6.1875f, 1.0f, 0.0f});
    expect_values(eval(t, -5.0f), {5, 1, 0});  // the first and last keys only shape the curve
    expect_values(eval(t, 2.5f), {7, 1, 0});
    t.tcb[1] = t.tcb[2] = Vec3f{1, 0, 0};  // full tension: zero tangents, 5 + 2 * (3/4 - 2/8)
    expect_values(eval(t, 1.5f), {6.0f, 1.0f, 0.0f});
    // Squad: keys 0, 0, 90, 90 degrees about z meet halfway at 45.
    Track r = make_track(Interpolation::KochanekBartels, 4, {0, 1, 2, 3}, {});
    for (float deg : {0.0f, 0.0f, 90.0f, 90.0f}) {
        const std::vector<float> q = quat_z(deg);
        r.values.insert(r.values.end(), q.begin(), q.end());
    }
    expect_values(eval(r, 1.5f), quat_z(45));
    const std::vector<float> before = eval(r, 1.25f);
    for (int c = 8; c < 12; ++c) r.values[size_t(c)] = -r.values[size_t(c)];  // an inner key on the other hemisphere
    expect_values(eval(r, 1.25f), before);
    EXPECT_GT(before[2], quat_z(0)[2]);
    EXPECT_LT(before[2], quat_z(45)[2]);
}

TEST(Animation, FrameCount) {
    Animation a;
    EXPECT_EQ(a.frame_count(), 1);
    a.start = 1.0f, a.end = 3.0f, a.frames_per_second = 10.0f;
    EXPECT_EQ(a.frame_count(), 21);
    EXPECT_FLOAT_EQ(a.frame_time(20), 3.0f);
    a.start = 0.0f, a.end = 20.0f, a.frames_per_second = 799.0f / 20.0f;  // BART kitchen: 800 frames
    EXPECT_EQ(a.frame_count(), 800);
}

Mesh triangle_mesh(Vec3f offset = {0, 0, 0}) {
    Mesh m;
    m.positions = {offset + Vec3f{0, 0, 0}, offset + Vec3f{1, 0, 0}, offset + Vec3f{0, 1, 0}};
    m.normals = {Vec3f{0, 0, 1}, Vec3f{0, 0, 1}, Vec3f{0, 0, 1}};
    m.indices = {0, 1, 2};
    return m;
}

void expect_near3(Vec3f a, Vec3f b, float tol = 1e-5f) {
    EXPECT_NEAR(a.x, b.x, tol);
    EXPECT_NEAR(a.y, b.y, tol);
    EXPECT_NEAR(a.z, b.z, tol);
}

// Parent: rotation 0 -> 90 degrees about z over [0, 1]; child: translation (1,0,0) -> (3,0,0) over [0, 2];
// instance 0 under the child with a local scale of 2; instance 1 static; mesh 2 has vertex keyframes over [0, 1].
Scene hierarchy_scene() {
    Scene s;
    s.meshes = {triangle_mesh(), triangle_mesh(), triangle_mesh()};
    s.instances = {Instance{0, Affine3f::identity()}, Instance{1, Affine3f::identity()}, Instance{2, Affine3f::identity()}};
    AnimatedNode parent;
    parent.rotation_track = make_track(Interpolation::Linear, 4, {0, 1}, {});
    for (float deg : {0.0f, 90.0f}) {
        const std::vector<float> q = quat_z(deg);
        parent.rotation_track.values.insert(parent.rotation_track.values.end(), q.begin(), q.end());
    }
    parent.visibility = make_track(Interpolation::Step, 1, {0, 3}, {1, 0});
    AnimatedNode child;
    child.parent = 0;
    child.translation_track = make_track(Interpolation::Linear, 3, {0, 2}, {1, 0, 0, 3, 0, 0});
    s.animation.nodes = {parent, child};
    s.animation.instances.push_back(InstanceAnimation{0, 1, Affine3f::scale({2, 2, 2})});
    VertexKeyframes vk;
    vk.mesh = 2;
    vk.times = {0, 1};
    vk.positions = {s.meshes[2].positions, triangle_mesh({0, 0, 4}).positions};
    s.animation.vertex_keyframes.push_back(vk);
    s.animation.end = 3.0f;
    s.finalize();
    return s;
}

TEST(Animation, SetTimeComposesParentsFirst) {
    Scene s = hierarchy_scene();
    s.set_time(1.0f);
    // world(child) = R90z * T(2,0,0); the instance adds S(2): (1,0,0) -> R90z (2+2, 0, 0) = (0, 4, 0).
    const Affine3f& m = s.instances[0].transform;
    expect_near3(m.transform_point({1, 0, 0}), {0, 4, 0});
    expect_near3(m.transform_point({0, 0, 0}), {0, 2, 0});
    expect_near3(s.meshes[2].positions[0], {0, 0, 4});
    s.set_time(0.5f);  // R45z * T(1.5,0,0) * S(2)
    const float c = std::sqrt(0.5f);
    expect_near3(s.instances[0].transform.transform_point({0, 0, 0}), {1.5f * c, 1.5f * c, 0});
    expect_near3(s.meshes[2].positions[1], {1, 0, 2});
    EXPECT_FLOAT_EQ(s.time, 0.5f);
    EXPECT_TRUE(s.instances[0].visible);
    s.set_time(3.0f);
    EXPECT_FALSE(s.instances[0].visible);
    EXPECT_TRUE(s.instances[1].visible);
}

TEST(Animation, GeometryChangeNamesWhatMoved) {
    Scene s = hierarchy_scene();
    GeometryChange first = s.set_time(0.0f);  // everything animated
    EXPECT_EQ(first.meshes, std::vector<uint32_t>({2}));
    EXPECT_EQ(first.instances, std::vector<uint32_t>({0, 2}));
    EXPECT_FALSE(first.camera);
    EXPECT_FALSE(s.set_time(0.0f).geometry());  // nothing moved
    GeometryChange both = s.set_time(0.5f);
    EXPECT_EQ(both.meshes, std::vector<uint32_t>({2}));
    EXPECT_EQ(both.instances, std::vector<uint32_t>({0, 2}));
    s.set_time(1.5f);
    GeometryChange rigid = s.set_time(2.0f);  // the keyframes are clamped since 1, the child moves until 2
    EXPECT_TRUE(rigid.meshes.empty());
    EXPECT_EQ(rigid.instances, std::vector<uint32_t>({0}));
    EXPECT_FALSE(s.set_time(2.5f).geometry());
    EXPECT_EQ(s.set_time(3.0f).instances, std::vector<uint32_t>({0}));  // hidden
    EXPECT_EQ(s.set_time(0.25f).instances, std::vector<uint32_t>({0, 2}));  // backwards in time

    Scene still;
    still.meshes = {triangle_mesh()};
    still.finalize();
    EXPECT_FALSE(still.set_time(1.0f).geometry());
}

TEST(Animation, CameraTracksAndNode) {
    Scene s = hierarchy_scene();
    s.camera = Camera{};
    s.camera->eye = {0, 0, 5};
    s.camera->target = {0, 0, 0};
    CameraAnimation cam;
    cam.node = 0;  // turned with the parent
    cam.vfov_degrees = make_track(Interpolation::Linear, 1, {0, 1}, {30, 60});
    s.animation.camera = cam;
    s.finalize();
    GeometryChange c = s.set_time(1.0f);
    EXPECT_TRUE(c.camera);
    EXPECT_NEAR(s.camera->vfov_degrees, 60.0f, 1e-4f);
    expect_near3(s.camera->eye, {0, 0, 5});
    expect_near3(s.camera->up, {-1, 0, 0});  // +y turned 90 degrees about z
    EXPECT_FALSE(s.set_time(2.0f).camera);
    EXPECT_TRUE(s.set_time(0.5f).camera);
    EXPECT_NEAR(s.camera->vfov_degrees, 45.0f, 1e-4f);
}

TEST(Animation, MorphTargetsThenSkinning) {
    Scene s;
    s.meshes = {triangle_mesh()};
    AnimatedNode root, moved;
    moved.translation_track = make_track(Interpolation::Linear, 3, {0, 1}, {0, 0, 0, 10, 0, 0});
    s.animation.nodes = {root, moved};
    MorphTargets morph;
    morph.mesh = 0;
    morph.position_deltas = {{Vec3f{0, 1, 0}, Vec3f{0, 0, 0}, Vec3f{0, 0, 0}}};
    morph.weights = make_track(Interpolation::Linear, 1, {0, 1}, {0, 0.5f});
    s.animation.morphs.push_back(morph);
    Skin skin;
    skin.mesh = 0;
    skin.joints = {0, 1};
    skin.inverse_bind = {Affine3f::identity(), Affine3f::identity()};
    skin.vertex_joints = {{0, 0, 0, 0}, {0, 1, 0, 0}, {1, 0, 0, 0}};
    skin.vertex_weights = {Vec4f{1, 0, 0, 0}, Vec4f{0.5f, 0.5f, 0, 0}, Vec4f{1, 0, 0, 0}};
    s.animation.skins.push_back(skin);
    s.finalize();
    ASSERT_EQ(s.animation.rest_positions[0].size(), 3u);
    GeometryChange c = s.set_time(1.0f);
    EXPECT_EQ(c.meshes, std::vector<uint32_t>({0}));
    expect_near3(s.meshes[0].positions[0], {0, 0.5f, 0});  // morphed, joint 0 (identity)
    expect_near3(s.meshes[0].positions[1], {6, 0, 0});     // half of joint 1's +10
    expect_near3(s.meshes[0].positions[2], {10, 1, 0});
    expect_near3(s.meshes[0].normals[1], {0, 0, 1});
    s.set_time(0.0f);  // from the rest positions again, not from the last result
    expect_near3(s.meshes[0].positions[0], {0, 0, 0});
    expect_near3(s.meshes[0].positions[2], {0, 1, 0});
}

TEST(Animation, SkinnedNormalsUseTheInverseTranspose) {
    Scene s;
    s.meshes = {triangle_mesh()};
    s.meshes[0].normals = {normalize(Vec3f{1, 1, 0}), normalize(Vec3f{1, 1, 0}), normalize(Vec3f{1, 1, 0})};
    AnimatedNode joint;
    joint.scale = {2, 1, 1};  // a non-uniform scale: normals scale by 1/2 in x
    s.animation.nodes = {joint};
    Skin skin;
    skin.joints = {0};
    skin.inverse_bind = {Affine3f::identity()};
    skin.vertex_joints.assign(3, {0, 0, 0, 0});
    skin.vertex_weights.assign(3, Vec4f{1, 0, 0, 0});
    s.animation.skins.push_back(skin);
    s.finalize();
    s.set_time(0.0f);
    expect_near3(s.meshes[0].normals[0], normalize(Vec3f{0.5f, 1, 0}));
    expect_near3(s.meshes[0].positions[1], {2, 0, 0});
}

// finalize's message for a scene broken by `breaker`.
std::string finalize_error(void (*breaker)(Scene&)) {
    Scene s = hierarchy_scene();
    breaker(s);
    try {
        s.finalize();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

TEST(Animation, MalformedDataGivesOneLineErrors) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    struct Case {
        void (*breaker)(Scene&);
        const char* expected;
    };
    static float g_nan;
    g_nan = nan;
    const Case cases[] = {
        {[](Scene& s) { s.animation.nodes[1].translation_track.times = {1, 1}; }, "times must increase"},
        {[](Scene& s) { s.animation.nodes[1].translation_track.times = {2, 1}; }, "times must increase"},
        {[](Scene& s) { s.animation.nodes[1].translation_track.values[4] = g_nan; }, "not finite"},
        {[](Scene& s) { s.animation.nodes[1].translation_track.times[0] = g_nan; }, "not finite"},
        {[](Scene& s) { s.animation.nodes[1].translation_track.values.pop_back(); }, "values for 2 keys"},
        {[](Scene& s) { s.animation.nodes[0].rotation_track.width = 3; }, "width 3, expected 4"},
        {[](Scene& s) { s.animation.nodes[1].parent = 1; }, "parent 1 is not an earlier node"},
        {[](Scene& s) { s.animation.instances[0].instance = 7; }, "instance 7 of 3"},
        {[](Scene& s) { s.animation.instances[0].node = 9; }, "node 9 of 2"},
        {[](Scene& s) { s.animation.vertex_keyframes[0].positions[1].pop_back(); }, "has 2 vertices, the mesh 3"},
        {[](Scene& s) { s.animation.vertex_keyframes[0].mesh = 5; }, "mesh 5 of 3"},
        {[](Scene& s) { s.animation.vertex_keyframes[0].times = {0}; }, "2 position sets for 1 times"},
        {[](Scene& s) {
             s.animation.nodes[1].translation_track.interpolation = Interpolation::KochanekBartels;
             s.animation.nodes[1].translation_track.tcb.assign(2, Vec3f{0, 0, 0});
         },
         "at least 4 keys"},
        {[](Scene& s) {
             Skin skin;
             skin.mesh = 0;
             skin.joints = {4};
             s.animation.skins.push_back(skin);
         },
         "joint node 4 of 2"},
        {[](Scene& s) {
             MorphTargets m;
             m.mesh = 1;
             m.position_deltas = {{Vec3f{}, Vec3f{}}};
             s.animation.morphs.push_back(m);
         },
         "has 2 vertices, the mesh 3"},
        {[](Scene& s) { s.animation.end = -1.0f; }, "start <= end"},
        {[](Scene& s) { s.animation.frames_per_second = 0.0f; }, "frames per second"},
    };
    for (const Case& c : cases) {
        const std::string message = finalize_error(c.breaker);
        SCOPED_TRACE(c.expected);
        EXPECT_NE(message.find(c.expected), std::string::npos) << message;
        EXPECT_EQ(message.rfind("animation: ", 0), 0u) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

}  // namespace
}  // namespace rf

// JSON scene keys (src/io/json_scene_loader.cpp): keyframed placements.
#include <fstream>

#include "rayforge/io/scene_io.h"
#include "scene_load_error.h"
#include "test_paths.h"

namespace rf {
namespace {

std::string write_json(const std::string& name, const std::string& text) {
    const std::string path = test::temp_dir("animation_json") + "/" + name;
    std::ofstream(path) << text;
    return path;
}

TEST(AnimationJson, KeyedTransformsMoveTheirInstances) {
    const std::string path = write_json("keys.json", R"({"meshes": [
      {"file": "builtin:cube"},
      {"file": "builtin:cube", "transform": {"translate": [0, 5, 0]},
       "animation": {"keys": [
         {"time": 1, "translate": [0, 0, 0], "rotate": {"axis": [0, 0, 1], "degrees": 0}},
         {"time": 3, "translate": [4, 0, 0], "rotate": {"quaternion": [0, 0, 1, 0]}, "scale": 2}]}}]})");
    Scene s = load_scene(path);
    ASSERT_EQ(s.instances.size(), 2u);
    EXPECT_FLOAT_EQ(s.animation.start, 1.0f);
    EXPECT_FLOAT_EQ(s.animation.end, 3.0f);
    expect_near3(s.instances[1].transform.transform_point({0, 0, 0}), {0, 10, 0});  // at the start: the lone scale key holds from the start
    GeometryChange c = s.set_time(2.0f);
    EXPECT_EQ(c.instances, std::vector<uint32_t>({1}));
    // keys(2) = T(2,0,0) * R(90 about z) * S(2), after the entry's transform T(0,5,0): (0,5,0) -> (0,10,0) -> (-10,0,0) -> (-8,0,0).
    expect_near3(s.instances[1].transform.transform_point({0, 0, 0}), {-8, 0, 0});
    expect_near3(s.instances[0].transform.transform_point({0, 0, 0}), {0, 0, 0});
}

TEST(AnimationJson, StepKeysAndErrors) {
    Scene s = load_scene(write_json("step.json", R"({"meshes": [{"file": "builtin:cube",
       "animation": {"interpolation": "step", "keys": [{"time": 0, "translate": [0, 0, 0]}, {"time": 1, "translate": [1, 0, 0]}]}}]})"));
    s.set_time(0.99f);
    expect_near3(s.instances[0].transform.transform_point({0, 0, 0}), {0, 0, 0});
    s.set_time(1.0f);
    expect_near3(s.instances[0].transform.transform_point({0, 0, 0}), {1, 0, 0});
    const std::pair<const char*, const char*> bad[] = {
        {R"({"time": 1, "translate": [0, 0, 0]}, {"time": 1, "translate": [1, 0, 0]})", "meshes[0].animation.keys[1].time: times must increase"},
        {R"({"time": 0, "rotate": {"axis": [0, 0, 0], "degrees": 3}})", "meshes[0].animation.keys[0].rotate.axis: axis must not be zero"},
        {R"({"time": 0, "spin": 1})", "unknown key"},
        {R"({"translate": [0, 0, 0]})", "missing \"time\""},
        {R"({"time": 0, "scale": 0})", "scale must not be zero"},
    };
    for (const auto& [keys, expected] : bad) {
        const std::string message = test::load_error(write_json(
            "bad.json", std::string(R"({"meshes": [{"file": "builtin:cube", "animation": {"keys": [)") + keys + "]}}]}"));
        EXPECT_NE(message.find(expected), std::string::npos) << message;
        EXPECT_EQ(message.find('\n'), std::string::npos) << message;
    }
}

// The flat triangles of `json` at time t against `part` at t placed by
// `placements` (one per copy, in order): equal vertex for vertex (a hidden
// triangle collapses to a point in both).
void expect_placed_copies(Scene& json, Scene& part, float t, const std::vector<Affine3f>& placements,
                          const std::string& what) {
    json.set_time(t);
    part.set_time(t);
    const SceneGeometry g = SceneGeometry::build(json), p = SceneGeometry::build(part);
    ASSERT_EQ(g.triangles.size(), p.triangles.size() * placements.size()) << what;
    for (size_t k = 0; k < placements.size(); ++k)
        for (size_t i = 0; i < p.triangles.size(); ++i) {
            const Triangle& got = g.triangles[k * p.triangles.size() + i];
            const Triangle& want = p.triangles[i];
            if (want.area() == 0.0f) {
                EXPECT_EQ(got.area(), 0.0f) << what << " copy " << k << " triangle " << i << " at t = " << t;
                continue;
            }
            const Vec3f a = placements[k].transform_point(want.v0), b = placements[k].transform_point(want.v1);
            const float tolerance = 1e-4f * std::max(1.0f, max_component(abs(a)));
            EXPECT_LE(max_component(abs(got.v0 - a)), tolerance) << what << " copy " << k << " triangle " << i << " at t = " << t;
            EXPECT_LE(max_component(abs(got.v1 - b)), tolerance) << what << " copy " << k << " triangle " << i << " at t = " << t;
        }
}

// A referenced file's own animation plays in the JSON scene: BART keys,
// visibility and an animated triangle placed twice (the second copy also
// under the entry's keys), and a skinned, morphing glTF figure placed once.
TEST(AnimationJson, ReferencedFilesKeepTheirAnimations) {
    const std::string aff = test::data_path("aff/animated.aff");
    Scene json = load_scene(write_json("placed.json", R"({"meshes": [
      {"file": ")" + aff + R"(", "transform": {"translate": [10, 0, 0]}},
      {"file": ")" + aff + R"(", "transform": {"translate": [0, 10, 0]},
       "animation": {"keys": [{"time": 1, "translate": [0, 0, 0]}, {"time": 3, "translate": [0, 0, 6]}]}}]})"));
    Scene part = load_scene(aff);
    EXPECT_FLOAT_EQ(json.animation.start, part.animation.start);
    EXPECT_FLOAT_EQ(json.animation.end, part.animation.end);
    EXPECT_FLOAT_EQ(json.animation.frames_per_second, part.animation.frames_per_second);
    for (float t : {1.0f, 1.6f, 2.2f, 3.0f}) {
        const Affine3f keys = Affine3f::translation({0.0f, 0.0f, 3.0f * (t - 1.0f)});
        expect_placed_copies(json, part, t,
                             {Affine3f::translation({10, 0, 0}), keys * Affine3f::translation({0, 10, 0})}, "animated.aff");
    }

    Scene skinned_json = load_scene(write_json("skinned.json", R"({"meshes": [
      {"file": "builtin:skinned", "transform": {"translate": [3, 0, 0], "scale": 2}}]})"));
    Scene skinned = load_scene("builtin:skinned");
    ASSERT_FALSE(skinned.animation.skins.empty());
    for (float t : {0.0f, 0.45f, 1.3f})
        expect_placed_copies(skinned_json, skinned, t,
                             {Affine3f::translation({3, 0, 0}) * Affine3f::scale(Vec3f(2.0f))}, "builtin:skinned");

    const std::string twice = test::load_error(write_json("skinned_twice.json", R"({"meshes": [
      {"file": "builtin:skinned"}, {"file": "builtin:skinned", "transform": {"translate": [3, 0, 0]}}]})"));
    EXPECT_NE(twice.find("meshes[1].file: a skinned file can be placed once"), std::string::npos) << twice;
    EXPECT_EQ(twice.find('\n'), std::string::npos) << twice;
}

}  // namespace
}  // namespace rf
