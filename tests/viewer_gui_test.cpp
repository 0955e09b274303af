// `rayforge view` end to end, in a real window under Xvfb with Mesa's
// software OpenGL, driven by scripts: the viewer shows what `rayforge
// render` writes for the same arguments (a paged scene file too), switches
// structure and integrator live, returns to the same image after orbit and
// reset, keeps its scene when a malformed file is dropped on it, and fails
// a script with the script's file and line. Skips with a message when no X server can be
// started or the viewer was not built.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "cli_runner.h"
#include "rayforge/io/image_io.h"
#include "rayforge/scene/camera.h"
#include "test_paths.h"

namespace rf {
namespace {

// xvfb-run with a screen large enough for the window; -a finds a free display.
// Under AddressSanitizer the viewer runs without leak detection: Mesa's
// driver, unloaded before the leak check, leaves allocations LeakSanitizer
// can neither attribute nor suppress by name. ASan's other checks stay on
// here, and the viewer's own code (session, settings, scripts) is
// leak-checked by the window-less tests.
// Parallel test processes start from display numbers of their own (-n), so
// two xvfb-run -a do not race for the same free number.
std::string xvfb() {
    static int launches = 0;
    const int first_display = 100 + int(getpid() % 400) * 16 + (launches++ % 16);
    return "env ASAN_OPTIONS=\"${ASAN_OPTIONS:-}:detect_leaks=0\" xvfb-run -a -n " + std::to_string(first_display) +
           " -s '-screen 0 1024x768x24'";
}

std::string write_script(const std::string& dir, const std::string& name, const std::string& text) {
    const std::string path = dir + "/" + name;
    std::ofstream(path) << text;
    return path;
}

// Why the viewer cannot run here ("" when it can), found once.
const std::string& gui_unavailable() {
    static const std::string why = [] {
        if (std::system("command -v xvfb-run >/dev/null 2>&1") != 0) return std::string("xvfb-run is not installed");
        const std::string dir = test::temp_dir("viewer_probe");
        const std::string script = write_script(dir, "quit.txt", "quit\n");
        const test::CliResult r = test::run_cli_inside(xvfb(), "view builtin:cornell --res 8x8 --spp 1 --script '" + script + "'");
        if (r.exit_code == 0) return std::string();
        return "the viewer cannot open a window here: " + (r.err.empty() ? std::string("exit ") + std::to_string(r.exit_code) : r.err);
    }();
    return why;
}

#define SKIP_WITHOUT_GUI()                                               \
    do {                                                                 \
        if (!gui_unavailable().empty()) GTEST_SKIP() << gui_unavailable(); \
    } while (0)

// Runs the viewer on `scene` with `options` and the script `text`.
test::CliResult view(const std::string& dir, const std::string& scene, const std::string& options, const std::string& text) {
    const std::string script = write_script(dir, "script.txt", text);
    return test::run_cli_inside(xvfb(), "view " + scene + " " + options + " --script '" + script + "' --script-timeout 60");
}

// The largest difference of any channel (linear values after decoding).
float max_difference(const Image& a, const Image& b) {
    if (a.width != b.width || a.height != b.height) return INFINITY;
    float worst = 0.0f;
    for (size_t i = 0; i < a.pixels.size(); ++i)
        for (int k = 0; k < 3; ++k) worst = std::max(worst, std::fabs(a.pixels[i][k] - b.pixels[i][k]));
    return worst;
}

// The same image "within a tolerance": on the CPU the viewer's PNG holds the
// very bytes `render` writes, so the tolerance is one 8-bit code at most.
void expect_same_image(const std::string& a, const std::string& b) {
    const Image x = read_image(a), y = read_image(b);
    ASSERT_EQ(x.width, y.width) << a << " vs " << b;
    EXPECT_LE(max_difference(x, y), 1.0f / 255.0f) << a << " vs " << b;
}

const char* kSmall = "--res 64x48 --spp 4";

TEST(ViewerGui, DefaultSceneMatchesTheRenderCommand) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_default");
    const test::CliResult v = view(dir, "builtin:cornell", kSmall,
                                   "wait-passes 4\nscreenshot " + dir + "/v.png\nscreenshot " + dir + "/v.exr\n"
                                   "screenshot-window " + dir + "/window.png\nprint-stats\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    const test::CliResult r = test::run_cli("render builtin:cornell " + std::string(kSmall) + " -q -o " + dir +
                                            "/r.png -o " + dir + "/r.exr");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    expect_same_image(dir + "/v.png", dir + "/r.png");
    EXPECT_EQ(max_difference(read_image(dir + "/v.exr"), read_image(dir + "/r.exr")), 0.0f);
    EXPECT_GT(read_image(dir + "/window.png").width, 64);  // the window, panel and all
    const auto stats = nlohmann::json::parse(test::lines_of(v.out).back());
    EXPECT_EQ(stats["passes"], 4);
    EXPECT_EQ(stats["scene"], "builtin:cornell");
    EXPECT_GT(stats["first_image_ms"].get<double>(), 0.0);
}

// An animated scene plays from a script (the structure updated each frame),
// pauses, and at a scrubbed time shows what `render --time` renders.
TEST(ViewerGui, PlaysAnAnimationAndAScrubbedTimeMatchesRenderTime) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_animation");
    const std::string options = std::string(kSmall) + " --update refit";
    const test::CliResult v = view(dir, "builtin:nbody@3k", options,
                                   "wait-passes 4\nplay\nwait-frames 4\nprint-stats\npause\ntime 2\n"
                                   "wait-passes 4\nscreenshot " + dir + "/v.png\nprint-stats\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    const std::vector<std::string> lines = test::lines_of(v.out);
    ASSERT_GE(lines.size(), 2u) << v.out;
    const auto playing = nlohmann::json::parse(lines[lines.size() - 2]);
    EXPECT_EQ(playing["animation"]["playing"], true);
    EXPECT_GE(playing["animation"]["updates"].get<int>(), 1);
    EXPECT_EQ(playing["animation"]["method"], "refit");
    const auto paused = nlohmann::json::parse(lines.back());
    EXPECT_EQ(paused["animation"]["playing"], false);
    EXPECT_EQ(paused["animation"]["time"], 2.0);
    const test::CliResult r =
        test::run_cli("render builtin:nbody@3k " + std::string(kSmall) + " --time 2 -q -o " + dir + "/r.png");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    expect_same_image(dir + "/v.png", dir + "/r.png");
}

TEST(ViewerGui, SwitchingStructureAndIntegratorStillMatchesTheCli) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_switch");
    const test::CliResult v =
        view(dir, "builtin:cornell", kSmall,
             "wait-passes 4\nset accel kdtree\nset integrator ao\nset ao-samples 4\nwait-passes 4\nscreenshot " + dir +
                 "/a.png\nset accel grid-proximity\nset integrator whitted\nwait-passes 4\nscreenshot " + dir +
                 "/b.png\nset accel bvh\nset builder sbvh\nset layout bvh4\nset integrator path\nset max-depth 3\n"
                 "wait-passes 4\nscreenshot " + dir + "/c.png\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    const std::pair<const char*, const char*> cases[] = {
        {"a", "--accel kdtree --integrator ao --ao-samples 4"},
        {"b", "--accel grid-proximity --integrator whitted"},
        {"c", "--builder sbvh --layout bvh4 --integrator path --max-depth 3"},
    };
    for (const auto& [name, options] : cases) {
        const std::string out = dir + "/" + name + "_cli.png";
        const test::CliResult r = test::run_cli("render builtin:cornell " + std::string(kSmall) + " " + options + " -q -o " + out);
        ASSERT_EQ(r.exit_code, 0) << r.err;
        expect_same_image(dir + "/" + name + ".png", out);
    }
}

TEST(ViewerGui, OrbitThenResetReturnsAndThePrintedCameraRendersTheSameView) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_orbit");
    const test::CliResult v = view(dir, "builtin:cornell", kSmall,
                                   "wait-passes 4\nscreenshot " + dir + "/a.png\norbit 40 15\nwalk forward 0.3\n"
                                   "wait-passes 4\nscreenshot " + dir + "/b.png\nprint-camera\nprint-stats\nreset\n"
                                   "wait-passes 4\nscreenshot " + dir + "/c.png\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    expect_same_image(dir + "/a.png", dir + "/c.png");
    EXPECT_GT(max_difference(read_image(dir + "/a.png"), read_image(dir + "/b.png")), 0.1f);
    const std::vector<std::string> lines = test::lines_of(v.out);
    ASSERT_EQ(lines.size(), 2u) << v.out;
    const auto stats = nlohmann::json::parse(lines[1]);
    EXPECT_GT(stats["frames_shown"].get<int>(), 8) << "previews while moving";
    const test::CliResult r = test::run_cli("render builtin:cornell " + std::string(kSmall) + " --camera " + lines[0] +
                                            " -q -o " + dir + "/b_cli.png");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    expect_same_image(dir + "/b.png", dir + "/b_cli.png");
}

TEST(ViewerGui, MalformedSceneDroppedInShowsAnErrorAndKeepsTheScene) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_drop");
    std::ofstream(dir + "/bad.obj") << "v 0 0 0\nv 1 0 0\nf 1 2 9\n";
    const test::CliResult v = view(dir, "builtin:cornell", kSmall,
                                   "wait-passes 4\nscreenshot " + dir + "/a.png\ndrop " + dir + "/bad.obj\n"
                                   "expect-error bad.obj\ndrop " + dir + "/missing.ply\nexpect-error missing.ply\n"
                                   "wait-passes 4\nscreenshot " + dir + "/b.png\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    expect_same_image(dir + "/a.png", dir + "/b.png");
    EXPECT_NE(v.err.find("rayforge: viewer: "), std::string::npos) << v.err;
    EXPECT_NE(v.err.find("bad.obj:3"), std::string::npos) << v.err;  // the loader's file:line
}

TEST(ViewerGui, BookmarksPersistAcrossRuns) {
    SKIP_WITHOUT_GUI();
    const std::string dir = test::temp_dir("viewer_bookmarks");
    const std::string file = "--bookmarks " + dir + "/marks.json ";
    test::CliResult v = view(dir, "builtin:cornell", file + kSmall,
                             "wait-idle\norbit 25 5\nbookmark-save side\nreset\nwait-passes 4\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    v = view(dir, "builtin:cornell", file + kSmall,
             "wait-idle\nbookmark-load side\nwait-passes 4\nscreenshot " + dir + "/side.png\nprint-camera\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    const test::CliResult r = test::run_cli("render builtin:cornell " + std::string(kSmall) + " --camera " +
                                            test::lines_of(v.out).at(0) + " -q -o " + dir + "/side_cli.png");
    expect_same_image(dir + "/side.png", dir + "/side_cli.png");
}

// Script failures: the command's file and line, exit status 1. A typo is
// found before any window opens, so this part needs no display.
TEST(ViewerGui, ScriptFailuresNameTheLineAndExitNonZero) {
    const std::string dir = test::temp_dir("viewer_script_errors");
    const std::string typo = write_script(dir, "script.txt", "wait-passes 1\nfly to the moon\n");
    test::CliResult v = test::run_cli("view builtin:cornell " + std::string(kSmall) + " --script '" + typo + "'");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("script.txt:2: unknown command 'fly'"), std::string::npos) << v.err;
    SKIP_WITHOUT_GUI();
    v = view(dir, "builtin:cornell", kSmall, "wait-passes 2\nset spp 2\nwait-passes 5\nquit\n");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("script.txt:3: wait-passes 5: the image stops at 2 passes"), std::string::npos) << v.err;
    v = view(dir, "builtin:cornell", kSmall, "wait-passes 1\nexpect-error anything\nquit\n");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("script.txt:2: expect-error anything: expected an error"), std::string::npos) << v.err;
    v = view(dir, "builtin:cornell", kSmall, "set builder nonsense\n");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("script.txt:1: set: set builder nonsense"), std::string::npos) << v.err;
}


// A paged scene file (.rfpack) in the viewer: the image after N passes is
// `render`'s of the same file, camera and passes, before and after an
// orbit; an in-core scene loaded in between and the paged file dropped back
// on the window show theirs; print-stats carries the page caches; a
// structure setting is refused with the script's line. (The refusals that
// need no window come first.)
TEST(ViewerGui, PagedSceneMatchesTheRenderCommand) {
    const std::string dir = test::temp_dir("viewer_paged");
    const std::string pack = dir + "/spheres.rfpack";
    const test::CliResult convert = test::run_cli("convert builtin:spheres -o " + pack + " -q");
    ASSERT_EQ(convert.exit_code, 0) << convert.err;
    const std::string paged = std::string(kSmall) + " --memory-budget 4M";
    test::CliResult v = test::run_cli("view " + pack + " " + paged + " --device cuda");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("paged scenes render on the CPU"), std::string::npos) << v.err;
    v = test::run_cli("view " + pack + " " + std::string(kSmall) + " --memory-budget lots");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("--memory-budget"), std::string::npos) << v.err;
    v = test::run_cli("view " + pack + " " + std::string(kSmall) + " --light 1,2,3");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("not applied to paged scenes"), std::string::npos) << v.err;
    SKIP_WITHOUT_GUI();
    v = view(dir, pack, paged,
             "wait-passes 4\nscreenshot " + dir + "/a.png\nprint-stats\norbit 30 10\nwait-passes 4\nscreenshot " + dir +
                 "/b.png\nprint-camera\nload builtin:cornell\nset layout bvh4\nwait-passes 4\nscreenshot " + dir +
                 "/c.png\ndrop " + pack + "\nwait-passes 4\nscreenshot " + dir + "/d.png\nexpect-no-error\nquit\n");
    ASSERT_EQ(v.exit_code, 0) << v.err;
    const std::vector<std::string> lines = test::lines_of(v.out);
    ASSERT_EQ(lines.size(), 2u) << v.out;
    const std::pair<std::string, std::string> cases[] = {
        {"a", pack + " " + paged},
        {"b", pack + " " + paged + " --camera " + lines[1]},
        // Not the first scene: its file's path tracer does not apply, the viewer's integrator does. The
        // layout, set while it loads, is checked against the scene being loaded, not the paged one shown.
        {"c", "builtin:cornell " + std::string(kSmall) + " --integrator whitted --layout bvh4"},
        {"d", pack + " " + paged},
    };
    for (const auto& [name, arguments] : cases) {
        const std::string out = dir + "/" + name + "_cli.png";
        const test::CliResult r = test::run_cli("render " + arguments + " -q -o " + out);
        ASSERT_EQ(r.exit_code, 0) << r.err;
        expect_same_image(dir + "/" + name + ".png", out);
    }
    const auto stats = nlohmann::json::parse(lines[0]);
    EXPECT_EQ(stats["structure"], "paged/bvh");
    EXPECT_GT(stats["triangles"].get<double>(), 0.0);
    const auto& caches = stats["paged"]["caches"];
    EXPECT_GT(caches["geometry"]["slots"].get<int>(), 0);
    EXPECT_GT(caches["attributes"]["cached"].get<int>(), 0);
    EXPECT_TRUE(caches.contains("textures"));
    EXPECT_LE(stats["paged"]["budget_bytes"].get<double>(), 4.0 * 1024 * 1024);

    v = view(dir, pack, paged, "wait-idle\nset integrator ao\nset builder sbvh\nquit\n");
    EXPECT_EQ(v.exit_code, 1);
    EXPECT_NE(v.err.find("script.txt:3: set builder sbvh: "), std::string::npos) << v.err;
    EXPECT_NE(v.err.find("structure settings do not apply to a paged scene"), std::string::npos) << v.err;
}

// Real input: a left drag orbits (the target stays, the eye keeps its
// distance), W walks (eye and target move together along the view), R
// resets. xdotool sends the events to the window; the script prints the
// camera between them, and the driver waits for each line before acting.
TEST(ViewerGui, MouseDragOrbitsKeysWalkAndRResets) {
    SKIP_WITHOUT_GUI();
    if (std::system("command -v xdotool >/dev/null 2>&1") != 0) GTEST_SKIP() << "xdotool is not installed";
    const std::string dir = test::temp_dir("viewer_input");
    const std::string script = write_script(dir, "script.txt",
                                            "wait-passes 2\nprint-camera\nsleep 3\nprint-camera\nsleep 3\n"
                                            "print-camera\nsleep 3\nprint-camera\nquit\n");
    const std::string out = dir + "/out.txt";
    // Waits until the viewer has printed N lines (at most 60 s).
    const std::string wait_lines = "wait_lines() { i=0; while [ \"$(wc -l < '" + out +
                                   "' 2>/dev/null || echo 0)\" -lt \"$1\" ] && [ $i -lt 600 ]; do sleep 0.1; "
                                   "i=$((i+1)); done; }\n";
    std::ofstream(dir + "/drive.sh")
        << wait_lines << "'" << test::cli_path() << "' view builtin:cornell " << kSmall
        << " --window 640x480 --bookmarks '" << dir << "/marks.json' --script '" << script << "' >'" << out
        << "' 2>'" << dir << "/err.txt' &\npid=$!\nwait_lines 1\n"
        << "win=$(xdotool search --sync --name 'rayforge view' | head -1)\n"
        << "xdotool mousemove --window $win 400 240 mousedown 1 mousemove --window $win 420 244 sleep 0.05 "
           "mousemove --window $win 460 250 sleep 0.05 mousemove --window $win 500 260 mouseup 1\n"
        << "wait_lines 2\nxdotool key --window $win w w w\nwait_lines 3\nxdotool key --window $win r\n"
        << "wait $pid\necho $? > '" << dir << "/code.txt'\n";
    (void)std::system((xvfb() + " sh '" + dir + "/drive.sh' >/dev/null 2>&1").c_str());
    ASSERT_EQ(test::read_file(dir + "/code.txt"), "0\n") << test::read_file(dir + "/err.txt");
    const std::vector<std::string> lines = test::lines_of(test::read_file(out));
    ASSERT_EQ(lines.size(), 4u) << test::read_file(out);
    const Camera start = parse_camera(lines[0]), orbited = parse_camera(lines[1]), walked = parse_camera(lines[2]);
    const Camera reset = parse_camera(lines[3]);
    EXPECT_EQ(orbited.target, start.target);
    EXPECT_GT(length(orbited.eye - start.eye), 0.1f);
    EXPECT_NEAR(length(orbited.eye - orbited.target), length(start.eye - start.target), 1e-4f);
    const Vec3f step = walked.eye - orbited.eye;
    EXPECT_GT(length(step), 0.0f);
    EXPECT_NEAR(length(walked.target - orbited.target - step), 0.0f, 1e-5f);                           // together
    EXPECT_GT(dot(normalize(step), normalize(orbited.target - orbited.eye)), 0.999f);                 // forward
    EXPECT_EQ(reset.eye, start.eye);
    EXPECT_EQ(reset.target, start.target);
}

}  // namespace
}  // namespace rf
