// The viewer's engine side without a window: the camera controller's
// motions, bookmarks files, the script parser, the settings table, and the
// session's threads (loads, rebuilds, restarts, previews, failed loads,
// paged scenes) checked against renders made directly with the engine.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <thread>

#include "bookmarks.h"
#include "camera_controller.h"
#include "rayforge/core/error.h"
#include <nlohmann/json.hpp>

#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"
#include "script.h"
#include "session.h"
#include "test_paths.h"
#include "view_settings.h"
#include "viewer_stats.h"

namespace rf::viewer {
namespace {

constexpr float kDegree = 3.14159265f / 180.0f;

Camera test_camera() {
    Camera c;
    c.eye = {1, 2, 5};
    c.target = {1, 1, 0};
    c.up = {0, 1, 0};
    c.vfov_degrees = 50;
    return c;
}

float angle_between(Vec3f a, Vec3f b) { return std::acos(std::clamp(dot(normalize(a), normalize(b)), -1.0f, 1.0f)); }

void expect_near(Vec3f a, Vec3f b, float eps, const char* what) {
    EXPECT_NEAR(a.x, b.x, eps) << what;
    EXPECT_NEAR(a.y, b.y, eps) << what;
    EXPECT_NEAR(a.z, b.z, eps) << what;
}

// ---- camera controller

TEST(CameraController, OrbitKeepsTheDistanceAndAFullTurnComesBack) {
    CameraController c(test_camera(), 10.0f);
    const float distance = length(c.camera().eye - c.camera().target);
    c.orbit(90.0f, 0.0f);
    EXPECT_NEAR(length(c.camera().eye - c.camera().target), distance, 1e-4f);
    expect_near(c.camera().target, test_camera().target, 1e-6f, "orbit keeps the target");
    // Positive yaw moves the eye to its right.
    const CameraFrame before = CameraFrame::make(test_camera(), 1, 1);
    EXPECT_GT(dot(c.camera().eye - test_camera().eye, before.right), 0.0f);
    for (int i = 0; i < 3; ++i) c.orbit(90.0f, 0.0f);
    expect_near(c.camera().eye, test_camera().eye, 1e-4f, "four quarter turns");
}

TEST(CameraController, PitchStopsShortOfStraightUpOrDown) {
    CameraController c(test_camera(), 10.0f);
    c.orbit(0.0f, 30.0f);
    EXPECT_GT(c.camera().eye.y, test_camera().eye.y);  // positive pitch raises the eye
    c.orbit(0.0f, 500.0f);
    const Vec3f view = c.camera().target - c.camera().eye;
    EXPECT_NEAR(angle_between(view, {0, -1, 0}), 1.0f * kDegree, 1e-3f);  // a degree short of straight down
    EXPECT_NO_THROW((void)CameraFrame::make(c.camera(), 4, 4));
    c.look(0.0f, 500.0f);
    EXPECT_NEAR(angle_between(c.camera().target - c.camera().eye, {0, 1, 0}), 1.0f * kDegree, 1e-3f);
}

TEST(CameraController, LookTurnsAboutTheEye) {
    CameraController c(test_camera(), 10.0f);
    const CameraFrame before = CameraFrame::make(test_camera(), 1, 1);
    c.look(20.0f, 0.0f);
    expect_near(c.camera().eye, test_camera().eye, 1e-6f, "look keeps the eye");
    EXPECT_GT(dot(c.camera().target - c.camera().eye, before.right), 0.0f);  // turned right
    // Yaw is about the up axis: the heading turns by 20 degrees, the elevation stays.
    const auto flat = [](Vec3f v) { return Vec3f(v.x, 0.0f, v.z); };
    const Vec3f after = c.camera().target - c.camera().eye;
    EXPECT_NEAR(angle_between(flat(after), flat(before.forward)), 20.0f * kDegree, 1e-4f);
    EXPECT_NEAR(normalize(after).y, before.forward.y, 1e-5f);
}

TEST(CameraController, PanMovesThePointUnderTheCursorWithIt) {
    CameraController c(test_camera(), 10.0f);
    const int height = 200;
    c.pan(40.0f, 0.0f, height);
    // The old target now projects 40 pixels right of the centre.
    const CameraFrame f = CameraFrame::make(c.camera(), height, height);
    const Vec3f to_old = test_camera().target - c.camera().eye;
    const float x_ndc = dot(to_old, f.right) / dot(to_old, f.forward) / f.tan_half_fov;
    EXPECT_NEAR(x_ndc * height * 0.5f, 40.0f, 1e-2f);
    expect_near(c.camera().target - c.camera().eye, test_camera().target - test_camera().eye, 1e-5f, "same view");
}

TEST(CameraController, DollyWalkFovAndReset) {
    CameraController c(test_camera(), 10.0f);
    const float distance = length(test_camera().eye - test_camera().target);
    c.dolly(1.0f);
    EXPECT_NEAR(length(c.camera().eye - c.camera().target), distance * 0.85f, 1e-4f);
    c.dolly(1000.0f);  // never through the target
    EXPECT_GT(length(c.camera().eye - c.camera().target), 0.0f);
    c.reset();
    c.walk(WalkDirection::Forward, 0.5f, false);
    const Vec3f moved = c.camera().eye - test_camera().eye;
    EXPECT_NEAR(length(moved), 0.5f * c.walk_speed(), 1e-4f);
    EXPECT_NEAR(c.walk_speed(), 2.0f, 1e-6f);  // a fifth of the scene size per second
    c.reset();
    c.walk(WalkDirection::Up, 1.0f, true);
    expect_near(c.camera().eye - test_camera().eye, Vec3f(0, 4.0f * c.walk_speed(), 0), 1e-4f, "fast walks 4x");
    c.set_fov(400.0f);
    EXPECT_EQ(c.camera().vfov_degrees, 150.0f);
    c.reset();
    expect_near(c.camera().eye, test_camera().eye, 0.0f, "reset");
    EXPECT_THROW(c.set(Camera{.eye = {0, 0, 0}, .target = {0, 0, 0}}), Error);
    EXPECT_THROW((void)parse_walk_direction("sideways"), Error);
}

// ---- bookmarks

TEST(Bookmarks, RoundTripThroughTheFile) {
    Bookmarks b;
    Camera c = test_camera();
    c.eye = {0.1f, 1e-7f, -123456.789f};
    b.put({"nave", "sponza", c});
    b.put({"second", "", test_camera()});
    b.put({"nave", "sponza", test_camera()});  // replaces
    ASSERT_EQ(b.all().size(), 2u);
    const std::string path = test::temp_dir("bookmarks") + "/b.json";
    b.put({"nave", "sponza", c});
    b.save(path);
    const Bookmarks back = Bookmarks::load(path);
    ASSERT_EQ(back.all().size(), 2u);
    ASSERT_NE(back.find("nave"), nullptr);
    EXPECT_EQ(back.find("nave")->camera.eye, c.eye);  // floats survive exactly
    EXPECT_EQ(back.find("nave")->scene, "sponza");
    EXPECT_EQ(back.find("second")->camera.vfov_degrees, 50.0f);
    EXPECT_TRUE(Bookmarks(back).remove("nave"));
}

TEST(Bookmarks, MalformedFilesAreOneLineErrors) {
    const char* bad[] = {
        "", "[]", "{\"bookmarks\": 3}", "{\"format\": \"other\", \"bookmarks\": []}",
        "{\"version\": 99, \"bookmarks\": []}", "{\"bookmarks\": [{\"eye\": [0,0,1], \"target\": [0,0,0]}]}",
        "{\"bookmarks\": [{\"name\": \"a\", \"eye\": [0,0], \"target\": [0,0,0]}]}",
        "{\"bookmarks\": [{\"name\": \"a\", \"eye\": [0,0,1], \"target\": [0,0,1]}]}",
        "{\"bookmarks\": [{\"name\": \"a\", \"eye\": [0,0,1], \"target\": [0,0,0], \"fov\": 500}]}",
        "{\"bookmarks\": [{\"name\": \"a\", \"eye\": [0,\"x\",1], \"target\": [0,0,0]}]}",
        "{\"bookmarks\": [{\"name\": \"a\", \"eye\": [0,0,1e39], \"target\": [0,0,0]}]}",
    };
    for (const char* text : bad) {
        try {
            (void)Bookmarks::parse(text, "b.json");
            ADD_FAILURE() << "accepted: " << text;
        } catch (const Error& e) {
            const std::string what = e.what();
            EXPECT_EQ(what.rfind("b.json", 0), 0u) << what;
            EXPECT_EQ(what.find('\n'), std::string::npos) << what;
        }
    }
    EXPECT_THROW((void)Bookmarks::load(test::temp_dir("no_bookmarks") + "/missing.json"), Error);
}

// ---- scripts

TEST(Script, ParsesEveryCommand) {
    const std::string text =
        "# a comment\n\nwait-passes 16\nwait-frames 2\nwait-idle\nsleep 0.5\norbit 10 -5  # inline comment\n"
        "look 1 2\npan 3 4\ndolly -2\nwalk forward 0.5\nwalk up 1 fast\nfov 30\n"
        "camera 0,1,3.9,0,1,0,0,1,0,40\nreset\nbookmark-save my view\nbookmark-load my view\n"
        "set builder sbvh\nset res 320x200\nset device cpu\nload builtin:spheres\ndrop /tmp/a file.obj\n"
        "screenshot out dir/a.png\nscreenshot-window w.png\nexpect-error cannot read\nexpect-no-error\n"
        "print-camera\nprint-stats\nreset-stats\nplay\npause\ntime 1.25\nquit\n";
    const Script s = parse_script(text, "s.txt");
    ASSERT_EQ(s.commands.size(), 31u);
    EXPECT_EQ(s.commands[29].op, ScriptOp::Time);
    EXPECT_EQ(s.commands[29].a, 1.25);
    EXPECT_EQ(s.commands[0].op, ScriptOp::WaitPasses);
    EXPECT_EQ(s.commands[0].a, 16.0);
    EXPECT_EQ(s.commands[0].line, 3);
    EXPECT_EQ(s.commands[4].op, ScriptOp::Orbit);
    EXPECT_EQ(s.commands[4].b, -5.0);
    EXPECT_EQ(s.commands[9].word, "up");
    EXPECT_TRUE(s.commands[9].fast);
    EXPECT_EQ(s.commands[13].rest, "my view");
    EXPECT_EQ(s.commands[15].word, "builder");
    EXPECT_EQ(s.commands[15].rest, "sbvh");
    EXPECT_EQ(s.commands[19].rest, "/tmp/a file.obj");
    EXPECT_EQ(s.commands[22].rest, "cannot read");
    EXPECT_EQ(s.where(s.commands[4]), "s.txt:7");
}

TEST(Script, BadLinesNameTheirLine) {
    const std::pair<const char*, const char*> cases[] = {
        {"wait-passes 4\nfly away\n", "s.txt:2: unknown command 'fly'"},
        {"wait-passes\n", "s.txt:1: wait-passes: usage: wait-passes N"},
        {"wait-passes -1\n", "s.txt:1: wait-passes"},
        {"wait-passes 2.5\n", "s.txt:1: wait-passes"},
        {"orbit 1\n", "s.txt:1: orbit: usage"},
        {"orbit 1 x\n", "s.txt:1: orbit: expected a number"},
        {"walk sideways 1\n", "s.txt:1: walk: unknown walk direction"},
        {"walk forward 1 slow\n", "s.txt:1: walk: usage"},
        {"sleep 1e9\n", "s.txt:1: sleep"},
        {"set builder\n", "s.txt:1: set: usage"},
        {"set colour red\n", "s.txt:1: set: unknown setting 'colour'"},
        {"set builder quick\n", "s.txt:1: set: set builder quick"},
        {"set res 10\n", "s.txt:1: set: set res 10"},
        {"set device gpu\n", "s.txt:1: set"},
        {"camera 1,2,3\n", "s.txt:1: camera"},
        {"screenshot\n", "s.txt:1: screenshot: usage"},
        {"quit now\n", "s.txt:1: quit: usage"},
    };
    for (const auto& [text, expected] : cases) {
        try {
            (void)parse_script(text, "s.txt");
            ADD_FAILURE() << "accepted: " << text;
        } catch (const Error& e) {
            EXPECT_EQ(std::string(e.what()).rfind(expected, 0), 0u) << e.what();
        }
    }
    EXPECT_THROW((void)load_script(test::temp_dir("no_script") + "/missing.txt"), Error);
}

// ---- settings

TEST(ViewSettings, EverySettingReadsBackWhatItWrote) {
    ViewSettings s;
    for (const SettingInfo& info : setting_infos()) {
        const std::string value = get_setting(s, info.key);
        ViewSettings copy = s;
        if (info.key != "device") EXPECT_NO_THROW(set_setting(copy, info.key, value)) << info.key;
        EXPECT_EQ(changes_between(s, copy), 0u) << info.key;
        for (const std::string& choice : info.choices) {
            if (info.key == "gpu-kernel") continue;  // meaningful on a CUDA device only
            ViewSettings other = s;
            set_setting(other, info.key, choice);
            EXPECT_EQ(get_setting(other, info.key), choice) << info.key;
        }
    }
}

TEST(ViewSettings, BadValuesLeaveTheSettingsAlone) {
    ViewSettings s;
    const ViewSettings before = s;
    for (const auto& [key, value] : std::vector<std::pair<std::string, std::string>>{
             {"builder", "fast"}, {"leaf-size", "0"}, {"leaf-size", "4.5"}, {"exposure", "-1"}, {"res", "0x10"},
             {"res", "abc"}, {"scale", "nan"}, {"optimize", "maybe"}, {"motion-scale", "9"}, {"nope", "1"},
             {"max-depth", "1e9"}, {"spp", "0"}}) {
        EXPECT_THROW(set_setting(s, key, value), Error) << key << " " << value;
        EXPECT_EQ(changes_between(before, s), 0u) << key;
    }
}

TEST(ViewSettings, EachChangeSaysWhatItCosts) {
    const ViewSettings base;
    const auto cost = [&](const std::string& key, const std::string& value) {
        ViewSettings s = base;
        set_setting(s, key, value);
        return changes_between(base, s);
    };
    EXPECT_EQ(cost("builder", "sbvh"), unsigned(Effect::Rebuild));
    EXPECT_EQ(cost("accel", "kdtree"), unsigned(Effect::Rebuild));
    EXPECT_EQ(cost("integrator", "path"), unsigned(Effect::Restart));
    EXPECT_EQ(cost("res", "320x200"), unsigned(Effect::Restart));
    EXPECT_EQ(cost("exposure", "2"), unsigned(Effect::Retone));
    EXPECT_EQ(cost("tonemap", "aces"), unsigned(Effect::Retone));
    EXPECT_EQ(cost("threads", "1"), unsigned(Effect::Restart));
}

TEST(ViewSettings, PreviewFilmsAreSmallerAndOnePass) {
    ViewSettings s;
    set_setting(s, "res", "640x360");
    set_setting(s, "spp", "64");
    const RenderOptions full = film_options(s, false, 3);
    EXPECT_EQ(full.width, 640);
    EXPECT_EQ(full.spp, 64);
    const RenderOptions preview = film_options(s, true, 3);
    EXPECT_EQ(preview.width, 213);
    EXPECT_EQ(preview.height, 120);
    EXPECT_EQ(preview.spp, 1);
    set_setting(s, "scale", "0.5");
    EXPECT_EQ(film_options(s, false, 1).width, 320);
    EXPECT_EQ(auto_motion_divisor(120.0, 30.0), 2);
    EXPECT_EQ(auto_motion_divisor(10.0, 30.0), 1);
    EXPECT_EQ(auto_motion_divisor(1e6, 30.0), 8);
}

// ---- the session

// Polls `done` until it holds or 60 s pass.
template <class Done>
bool eventually(Done done) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < until) {
        if (done()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
}

SceneSource builtin(const std::string& name) { return {"builtin:" + name, "builtin:" + name, {}, {}}; }

ViewSettings small_settings() {
    ViewSettings s;
    set_setting(s, "res", "40x30");
    set_setting(s, "spp", "3");
    set_setting(s, "integrator", "whitted");
    return s;
}

// The frame shows everything asked so far and has `passes` passes.
std::shared_ptr<const Frame> settled_frame(Session& session, int passes) {
    std::shared_ptr<const Frame> frame;
    const bool ok = eventually([&] {
        frame = session.frame();
        return frame && session.versions().shown_by(*frame) && !frame->preview && frame->passes == passes;
    });
    EXPECT_TRUE(ok) << "no settled frame with " << passes << " passes; error: " << session.status().error;
    return ok ? frame : nullptr;
}

// An image as a display image's bytes (8-bit sRGB RGBA, as PNG output).
std::vector<uint8_t> display_bytes(const Image& image, const ToneMapping& tone) {
    std::vector<uint8_t> bytes(image.pixels.size() * 4, 255);
    for (size_t i = 0; i < image.pixels.size(); ++i) tone_map_srgb8(image.pixels[i], tone, &bytes[4 * i]);
    return bytes;
}

// What the engine renders for these settings and camera, as display bytes.
std::vector<uint8_t> reference(const SceneSource& source, const ViewSettings& s, const Camera& camera) {
    const std::unique_ptr<World> world = open_world(source.path, s.world);
    return display_bytes(render(*world, camera, film_options(s, false, 1)), s.tone);
}

std::vector<uint8_t> pixels_of(const Frame& frame) { return frame.image->download(); }

TEST(Session, ShowsTheSceneAsTheEngineRendersIt) {
    const ViewSettings s = small_settings();
    Session session(SessionConfig{s, {}});
    session.load(builtin("cornell"));
    const auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    const auto scene = session.scene();
    ASSERT_TRUE(scene);
    EXPECT_EQ(frame->image->width(), 40);
    EXPECT_EQ(frame->target_passes, 3);
    EXPECT_EQ(pixels_of(*frame), reference(builtin("cornell"), s, scene->camera));
    const SessionStatus status = session.status();
    EXPECT_EQ(status.scene_name, "builtin:cornell");
    EXPECT_EQ(status.accel.name, "bvh/binned/bvh8");
    EXPECT_EQ(status.error_count, 0u);
    // The film behind it.
    const Image film = session.film().get();
    EXPECT_EQ(film.width, 40);
}

TEST(Session, CameraSettingAndStructureChangesShowWhatTheyAskFor) {
    ViewSettings s = small_settings();
    Session session(SessionConfig{s, {}});
    session.load(builtin("cornell"));
    ASSERT_TRUE(settled_frame(session, 3));
    const auto scene = session.scene();

    Camera moved = scene->camera;
    moved.eye = moved.eye + Vec3f(0.3f, 0.2f, 0.0f);
    session.set_camera(moved, scene->id, false);
    auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), reference(builtin("cornell"), s, moved));

    set_setting(s, "integrator", "ao");
    set_setting(s, "builder", "sbvh");
    set_setting(s, "layout", "bvh2");
    session.set_settings(s);
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(session.status().accel.name, "bvh/sbvh/bvh2");
    EXPECT_EQ(pixels_of(*frame), reference(builtin("cornell"), s, moved));

    // Exposure re-tones the same passes without starting over.
    set_setting(s, "exposure", "0.25");
    session.set_settings(s);
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), reference(builtin("cornell"), s, moved));
    EXPECT_EQ(session.status().error_count, 0u);
}

// An animated scene: scrubbing shows the scene at that time as the engine
// renders it; playing advances the time and updates the structure each frame.
TEST(Session, ScrubsAndPlaysAnAnimation) {
    ViewSettings s = small_settings();
    set_setting(s, "update", "rebuild");
    Session session(SessionConfig{s, {}});
    const SceneSource source = builtin("nbody@3k");
    session.load(source);
    ASSERT_TRUE(settled_frame(session, 3));
    SessionStatus status = session.status();
    ASSERT_TRUE(status.animation.animated);
    EXPECT_EQ(status.animation.method, "rebuild");
    EXPECT_FALSE(status.animation.playing);
    const auto scene = session.scene();

    session.set_time(1.5f);
    ASSERT_TRUE(eventually([&] { return session.status().animation.time == 1.5f; }));
    const auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    const std::unique_ptr<World> later = open_world(source.path, s.world);  // a fresh world at 1.5 s
    later->set_time(1.5f);
    EXPECT_EQ(pixels_of(*frame), display_bytes(render(*later, scene->camera, film_options(s, false, 1)), s.tone));

    session.play(true);
    ASSERT_TRUE(eventually([&] {
        status = session.status();
        return status.animation.updates >= 3 && status.animation.time != 1.5f;
    })) << session.status().error;
    EXPECT_TRUE(status.animation.playing);
    EXPECT_GT(status.animation.mean_update_ms, 0.0);
    session.play(false);
    ASSERT_TRUE(eventually([&] { return !session.status().animation.playing; }));
    EXPECT_EQ(session.status().error_count, 0u);
}

TEST(Session, PreviewsWhileMovingThenFullResolution) {
    ViewSettings s = small_settings();
    set_setting(s, "motion-scale", "2");
    Session session(SessionConfig{s, {}});
    session.load(builtin("cornell"));
    ASSERT_TRUE(settled_frame(session, 3));
    const auto scene = session.scene();
    Camera c = scene->camera;
    c.eye = c.eye + Vec3f(0.1f, 0, 0);
    session.set_camera(c, scene->id, true);
    std::shared_ptr<const Frame> preview;
    ASSERT_TRUE(eventually([&] {
        preview = session.frame();
        return preview && preview->preview && preview->camera_version == session.versions().camera;
    }));
    EXPECT_EQ(preview->image->width(), 20);
    EXPECT_EQ(preview->image->height(), 15);
    EXPECT_EQ(preview->passes, 1);
    EXPECT_EQ(session.status().motion_divisor, 2);
    // A preview stops at one pass until the camera moves again or rests.
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    EXPECT_EQ(session.frame()->sequence, preview->sequence);
    session.set_camera(c, scene->id, false);
    const auto still = settled_frame(session, 3);
    ASSERT_TRUE(still);
    EXPECT_EQ(still->image->width(), 40);
    EXPECT_EQ(pixels_of(*still), reference(builtin("cornell"), s, c));
    // A camera for a scene no longer shown is dropped.
    const uint64_t version = session.versions().camera;
    session.set_camera(scene->camera, scene->id + 1, false);
    EXPECT_EQ(session.versions().camera, version);
}

TEST(Session, AFailedLoadKeepsTheSceneShown) {
    const std::string dir = test::temp_dir("session_bad_load");
    {
        std::ofstream bad(dir + "/bad.obj");
        bad << "v 0 0 0\nv 1 0 0\nf 1 2 7\n";
    }
    Session session(SessionConfig{small_settings(), {}});
    session.load(builtin("cornell"));
    const auto first = settled_frame(session, 3);
    ASSERT_TRUE(first);
    session.load({"bad.obj", dir + "/bad.obj", {}, {}});
    ASSERT_TRUE(eventually([&] { return session.status().error_count == 1 && !session.versions().jobs_pending; }));
    EXPECT_NE(session.status().error.find("bad.obj"), std::string::npos) << session.status().error;
    EXPECT_EQ(session.scene()->source.name, "builtin:cornell");
    EXPECT_EQ(session.frame()->sequence, first->sequence);
    // And the next good load replaces it.
    session.load(builtin("spheres"));
    ASSERT_TRUE(eventually([&] { return session.scene()->source.name == "builtin:spheres"; }));
    ASSERT_TRUE(settled_frame(session, 3));
}

TEST(Session, PrepareSetsTheFirstScenesSettingsAndCamera) {
    SessionConfig config{small_settings(), {}};
    Camera chosen;
    config.prepare = [&](World&, SceneData& data, bool first, ViewSettings& settings) {
        if (!first) return;
        settings.render.width = 24;
        settings.render.height = 16;
        data.camera.eye = data.camera.eye + Vec3f(0, 0.2f, 0);
        chosen = data.camera;
    };
    Session session(std::move(config));
    session.load(builtin("cornell"));
    const auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(frame->image->width(), 24);
    EXPECT_EQ(session.settings().render.width, 24);
    EXPECT_EQ(session.scene()->camera.eye, chosen.eye);
}

TEST(Session, StopsCleanlyWhateverItIsDoing) {
    for (int i = 0; i < 3; ++i) {
        ViewSettings s = small_settings();
        set_setting(s, "spp", "1000");
        set_setting(s, "integrator", "path");
        Session session(SessionConfig{s, {}});
        session.load(builtin("cornell"));
        if (i > 0) eventually([&] { return session.frame() != nullptr; });
        if (i == 2) {
            set_setting(s, "builder", "sweep");
            session.set_settings(s);
        }
    }  // destroyed mid-load, mid-render and mid-rebuild
    SUCCEED();
}

// ---- paged scenes

// Budgets far below the file (17 MiB), so pages are evicted and read again.
PagedSceneOptions small_budget() {
    PagedSceneOptions o;
    o.memory_budget = size_t(4) << 20;
    return o;
}

// builtin:spheres (220K triangles) as a paged file, written once.
const std::string& paged_spheres_path() {
    static const std::string path = [] {
        const std::string file = test::temp_dir("viewer_paged") + "/spheres.rfpack";
        Scene scene = make_builtin_scene("spheres");
        scene.finalize();
        (void)convert_to_paged(scene, file);
        return file;
    }();
    return path;
}

SceneSource paged_spheres() { return {"spheres.rfpack", paged_spheres_path(), {}, {}}; }

SessionConfig paged_config(ViewSettings s) {
    s.world.paged = small_budget();
    return SessionConfig{s, {}};
}

// The paged file as a world of its own (the budgets the session's have).
std::unique_ptr<World> paged_world() {
    WorldOptions options;
    options.paged = small_budget();
    return open_world(paged_spheres_path(), options);
}

// What a fresh paged world renders for these settings and camera, as display bytes.
std::vector<uint8_t> paged_reference(const ViewSettings& s, const Camera& camera) {
    const std::unique_ptr<World> world = paged_world();
    return display_bytes(render(*world, camera, film_options(s, false, 1)), s.tone);
}

TEST(SessionPaged, ShowsAPagedSceneAsThePagedRendererRendersIt) {
    const ViewSettings s = small_settings();
    Session session(paged_config(s));
    session.load(paged_spheres());
    const auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    const auto scene = session.scene();
    ASSERT_TRUE(scene && scene->kind == SceneKind::Paged);
    const std::unique_ptr<World> file = paged_world();
    EXPECT_EQ(scene->camera.eye, file->camera().eye);  // the file's camera
    EXPECT_EQ(frame->image->width(), 40);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, scene->camera));

    const SessionStatus status = session.status();
    EXPECT_EQ(status.error_count, 0u) << status.error;
    EXPECT_EQ(status.triangles, file->paged_scene().info().triangles);
    EXPECT_EQ(status.accel.name, "paged/bvh");
    ASSERT_EQ(status.paged.caches.size(), 3u);
    EXPECT_EQ(status.paged.caches[0].name, "geometry");
    EXPECT_EQ(status.paged.caches[1].name, "attributes");
    EXPECT_EQ(status.paged.caches[2].name, "textures");
    const PageCacheReport& geometry = status.paged.caches[0];
    EXPECT_GT(geometry.slots, 0u);
    EXPECT_LE(geometry.cached, geometry.slots);
    EXPECT_GT(geometry.requests, 0u);  // the last pass's
    EXPECT_LE(status.paged.budget_bytes, small_budget().memory_budget);
    EXPECT_LE(status.paged.cache_bytes, status.paged.budget_bytes);
    EXPECT_EQ(status.paged.resident_bytes, file->paged_scene().info().resident_bytes);

    // print-stats carries the same figures.
    const ViewerStats stats;
    const auto json = nlohmann::json::parse(stats.json(status, Clock::now()));
    EXPECT_EQ(json["structure"], "paged/bvh");
    EXPECT_EQ(json["paged"]["budget_bytes"], status.paged.budget_bytes);
    EXPECT_EQ(json["paged"]["caches"]["geometry"]["slots"], geometry.slots);
    EXPECT_EQ(json["paged"]["caches"]["geometry"]["bytes_read"], geometry.bytes_read);
    EXPECT_DOUBLE_EQ(json["paged"]["caches"]["geometry"]["hit_rate"].get<double>(), geometry.hit_rate());
    EXPECT_TRUE(json["paged"]["caches"].contains("textures"));
}

TEST(SessionPaged, CameraIntegratorAndExposureChangesWorkAsInCore) {
    ViewSettings s = small_settings();
    Session session(paged_config(s));
    session.load(paged_spheres());
    const auto first = settled_frame(session, 3);
    ASSERT_TRUE(first);
    const auto scene = session.scene();

    Camera moved = scene->camera;
    moved.eye = moved.eye + Vec3f(1.5f, 0.5f, -1.0f);
    session.set_camera(moved, scene->id, false);
    auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, moved));
    EXPECT_NE(pixels_of(*frame), pixels_of(*first));

    set_setting(s, "integrator", "path", SceneKind::Paged);
    set_setting(s, "max-depth", "2", SceneKind::Paged);
    set_setting(s, "res", "32x24", SceneKind::Paged);
    session.set_settings(s);
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(frame->image->width(), 32);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, moved));

    set_setting(s, "exposure", "0.5", SceneKind::Paged);
    session.set_settings(s);
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, moved));

    // A structure change that reaches the session anyway (the table refuses
    // it) builds nothing and still settles on the same image.
    s.world.build.builder = Builder::Sbvh;
    session.set_settings(s);
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, moved));
    EXPECT_EQ(session.status().accel.name, "paged/bvh");
    EXPECT_EQ(session.status().error_count, 0u) << session.status().error;
}

TEST(SessionPaged, StructureSettingsAndOtherDevicesAreRefused) {
    ViewSettings s = small_settings();
    const ViewSettings before = s;
    for (const SettingInfo& info : setting_infos()) {
        if (info.group != "structure") continue;
        EXPECT_FALSE(applies_to(info, SceneKind::Paged)) << info.key;
        EXPECT_TRUE(applies_to(info, SceneKind::InCore)) << info.key;
        const std::string value = get_setting(s, info.key);
        try {
            set_setting(s, info.key, value, SceneKind::Paged);
            ADD_FAILURE() << "accepted for a paged scene: " << info.key;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("do not apply to a paged scene"), std::string::npos) << e.what();
        }
    }
    try {
        set_setting(s, "builder", "sbvh", SceneKind::Paged);
        ADD_FAILURE() << "accepted set builder sbvh";
    } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()),
                  "set builder sbvh: structure settings do not apply to a paged scene (its structure is in the file)");
    }
    EXPECT_EQ(changes_between(before, s), 0u);
    EXPECT_NO_THROW(set_setting(s, "device", "cpu", SceneKind::Paged));
    try {
        set_setting(s, "device", "cuda", SceneKind::Paged);
        ADD_FAILURE() << "accepted set device cuda for a paged scene";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("paged scenes render on the CPU"), std::string::npos) << e.what();
    }
    EXPECT_NO_THROW(set_setting(s, "threads", "1", SceneKind::Paged));
    EXPECT_NO_THROW(set_setting(s, "builder", "sbvh", SceneKind::InCore));

    // A paged file asked for on a CUDA device fails its load with a clear error.
    ViewSettings cuda = small_settings();
    cuda.world.device = Device{Device::Kind::Cuda, 0};
    Session session(paged_config(cuda));
    session.load(paged_spheres());
    ASSERT_TRUE(eventually([&] { return session.status().error_count == 1 && !session.versions().jobs_pending; }));
    EXPECT_NE(session.status().error.find("paged scenes render on the CPU"), std::string::npos)
        << session.status().error;
    EXPECT_FALSE(session.scene());
}

TEST(SessionPaged, SwitchesBetweenInCoreAndPagedScenes) {
    const ViewSettings s = small_settings();
    Session session(paged_config(s));
    session.load(builtin("cornell"));
    ASSERT_TRUE(settled_frame(session, 3));

    session.load(paged_spheres());
    ASSERT_TRUE(eventually([&] { return session.scene()->kind == SceneKind::Paged; }));
    auto frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, session.scene()->camera));
    EXPECT_EQ(session.status().paged.caches.size(), 3u);

    session.load(builtin("cornell"));
    ASSERT_TRUE(eventually([&] { return session.scene()->source.name == "builtin:cornell"; }));
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), reference(builtin("cornell"), s, session.scene()->camera));
    EXPECT_EQ(session.status().accel.name, "bvh/binned/bvh8");
    EXPECT_TRUE(session.status().paged.caches.empty());

    session.load(paged_spheres());  // and back, opened afresh
    ASSERT_TRUE(eventually([&] { return session.scene()->kind == SceneKind::Paged; }));
    frame = settled_frame(session, 3);
    ASSERT_TRUE(frame);
    EXPECT_EQ(pixels_of(*frame), paged_reference(s, session.scene()->camera));
    EXPECT_EQ(session.status().error_count, 0u) << session.status().error;
}

}  // namespace
}  // namespace rf::viewer
