// The rayforge command line: help, info, render, and its error contract
// (exit 1 with one "rayforge: error:" line; exit 2 for usage errors).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "rayforge/backend/device.h"
#include "rayforge/io/image_io.h"
#include "cli_runner.h"
#include "test_paths.h"

namespace rf {
namespace {

using test::CliResult;
using test::lines_of;
using test::read_file;
using test::run_cli;

void expect_one_error_line(const CliResult& r) {
    EXPECT_EQ(r.exit_code, 1) << r.err;
    std::vector<std::string> lines = lines_of(r.err);
    ASSERT_EQ(lines.size(), 1u) << r.err;
    EXPECT_EQ(lines[0].rfind("rayforge: error: ", 0), 0u) << lines[0];
}

TEST(Cli, HelpForEveryVerbAndVersion) {
    for (const char* args : {"--help", "info --help", "render --help", "bench --help", "build --help"}) {
        CliResult r = run_cli(args);
        EXPECT_EQ(r.exit_code, 0) << args << ": " << r.err;
        EXPECT_NE(r.out.find("Usage"), std::string::npos) << args << ": " << r.out;
    }
    CliResult render_help = run_cli("render --help");
    for (const char* option : {"--res", "--spp", "--integrator", "--camera", "--threads", "--max-depth", "--ao-radius",
                               "--exposure", "--seed", "--rr-depth", "--light-sampling", "--tonemap", "--aov",
                               "--time-budget", "--env-map", "--reflection-depth", "--refraction-depth", "--shading",
                               "--device", "--gpu-kernel", "--build-on", "--wavefront", "--sort-rays"})
        EXPECT_NE(render_help.out.find(option), std::string::npos) << option;
    for (const char* option : {"--device", "--gpu-kernel", "--spp", "--build-on", "--build-stages"})
        EXPECT_NE(run_cli("bench --help").out.find(option), std::string::npos) << option;
    for (const char* option : {"--device", "--builder", "--reps", "--convert", "--threads"})
        EXPECT_NE(run_cli("build --help").out.find(option), std::string::npos) << option;
    EXPECT_NE(run_cli("info --help").out.find("--devices"), std::string::npos);
    CliResult version = run_cli("--version");
    EXPECT_EQ(version.exit_code, 0);
    EXPECT_EQ(version.out.rfind("rayforge ", 0), 0u) << version.out;
}

TEST(Cli, InfoPrintsTheCornellBoxContents) {
    CliResult r = run_cli("info builtin:cornell");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    for (const char* field : {"triangles:", "vertices:", "meshes:", "instances:", "bounds:", "materials:", "textures:",
                              "lights:", "camera:", "memory:"})
        EXPECT_NE(r.out.find(field), std::string::npos) << field << " missing in\n" << r.out;
    EXPECT_NE(r.out.find("emissive triangles"), std::string::npos) << r.out;
    CliResult verbose = run_cli("info --verbose builtin:cornell");
    EXPECT_EQ(verbose.exit_code, 0);
    EXPECT_GT(lines_of(verbose.out).size(), lines_of(r.out).size());
}

// --animation names a glTF clip; asked of a scene without glTF clips it
// would be ignored, so it is an error (one line, exit 1) for info and render.
TEST(Cli, AnimationClipOfASceneWithoutClipsIsAnError) {
    for (const char* command : {"info builtin:cornell --animation walk",
                                "render builtin:cornell --animation walk --res 8x8 -q -o unused.png"}) {
        CliResult r = run_cli(command);
        EXPECT_EQ(r.exit_code, 1) << command << "\n" << r.err;
        EXPECT_NE(r.err.find("--animation walk: builtin:cornell has no glTF animations"), std::string::npos) << r.err;
        EXPECT_EQ(lines_of(r.err).size(), 1u) << r.err;
    }
}

TEST(Cli, RenderWritesThePngAndOneSummaryLine) {
    std::string out = test::temp_dir("cli_render") + "/cornell.png";
    CliResult r = run_cli("render builtin:cornell -o '" + out + "' --res 64x48 --spp 1 --threads 2");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    ASSERT_TRUE(std::filesystem::exists(out));
    Image image = read_image(out);
    EXPECT_EQ(image.width, 64);
    EXPECT_EQ(image.height, 48);
    std::vector<std::string> lines = lines_of(r.out);
    ASSERT_EQ(lines.size(), 1u) << r.out;
    EXPECT_NE(lines[0].find(out), std::string::npos);
    EXPECT_NE(lines[0].find("render"), std::string::npos);

    // Other formats and integrators by name and extension.
    std::string exr = test::temp_dir("cli_render_exr") + "/normals.exr";
    r = run_cli("render builtin:cornell -o '" + exr + "' --res 16x12 --integrator normals "
                "--camera 0,1,3.5,0,1,0,0,1,0,40");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(read_image(exr).width, 16);
}

// An animation: one image per frame, named by the pattern, the structure
// updated between frames; --time renders one moment; bad frame ranges,
// patterns and update methods are one-line errors.
TEST(Cli, RenderFramesWritesOneImagePerFrame) {
    const std::string dir = test::temp_dir("cli_frames");
    for (const char* method : {"refit", "adapt", "two-level"}) {
        const std::string pattern = dir + "/" + method + "_%03d.png";
        const CliResult r = run_cli("render builtin:nbody@3k --frames 0:6:3 -o '" + pattern +
                                    "' --res 24x16 --threads 2 --update " + method);
        ASSERT_EQ(r.exit_code, 0) << r.err;
        for (const char* frame : {"000", "003", "006"})
            EXPECT_TRUE(std::filesystem::exists(dir + "/" + method + "_" + frame + ".png")) << method << frame;
        EXPECT_FALSE(std::filesystem::exists(dir + "/" + method + "_001.png"));
        // Each frame shows its own time (the bodies fly apart), not the first frame again.
        EXPECT_NE(read_image(dir + "/" + method + "_000.png").pixels, read_image(dir + "/" + method + "_006.png").pixels)
            << method;
        EXPECT_NE(r.out.find("frame 3 (t = 0.100 s): update"), std::string::npos) << r.out;
        EXPECT_NE(r.out.find(std::string("(") + method), std::string::npos) << r.out;
    }
    const std::string one = dir + "/at_time.png";
    ASSERT_EQ(run_cli("render builtin:nbody@3k --time 1.25 -o '" + one + "' --res 24x16").exit_code, 0);
    EXPECT_TRUE(std::filesystem::exists(one));

    expect_one_error_line(run_cli("render builtin:nbody@3k --frames 0:4 -o '" + dir + "/plain.png' --res 8x8"));
    expect_one_error_line(run_cli("render builtin:nbody@3k --frames 4:1:1 -o '" + dir + "/f%d.png' --res 8x8"));
    expect_one_error_line(run_cli("render builtin:nbody@3k --frames 0:x -o '" + dir + "/f%d.png' --res 8x8"));
    expect_one_error_line(run_cli("render builtin:nbody@3k --frames 0:1 -o '" + dir + "/f%s.png' --res 8x8"));
    expect_one_error_line(run_cli("render builtin:nbody@3k --frames 0:1 -o '" + dir + "/f%d.png' --update sideways"));
    expect_one_error_line(run_cli("render builtin:nbody@3k -o '" + dir + "/f.png' --adapt-reading third"));
}

TEST(Cli, PathRenderWritesEveryOutputAndTheAovs) {
    const std::string dir = test::temp_dir("cli_path");
    CliResult r = run_cli("render builtin:material-spheres -o '" + dir + "/spheres.png' -o '" + dir +
                          "/spheres.exr' --integrator path --res 24x18 --spp 2 --max-depth 3 --tonemap aces "
                          "--aov albedo,normal --aov depth --threads 2 -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("path 2 spp"), std::string::npos) << r.out;
    for (const char* name : {"spheres.png", "spheres.exr", "spheres.albedo.exr", "spheres.normal.exr", "spheres.depth.exr"}) {
        ASSERT_TRUE(std::filesystem::exists(dir + "/" + name)) << name;
        EXPECT_EQ(read_image(dir + "/" + name).width, 24) << name;
    }
    // An environment map from the command line and a time budget.
    r = run_cli("render builtin:furnace -o '" + dir + "/sky.pfm' --integrator path --res 8x6 --spp 100000 "
                "--time-budget 0.2 --env-map builtin:sky --env-strength 0.5 -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.out.find("100000 spp"), std::string::npos) << "the budget should stop the render: " << r.out;
    EXPECT_EQ(read_image(dir + "/sky.pfm").height, 6);
}

TEST(Cli, BenchMeasuresRenderingThroughput) {
    CliResult r = run_cli("bench --scene builtin:cornell --integrator path,whitted --res 32x24 --reps 1 --max-depth 2 "
                          "--threads 2 -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("rendering throughput"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("path"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("whitted"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("shading"), std::string::npos) << r.out;
}

TEST(Cli, RuntimeErrorsAreOneLineAndExitOne) {
    expect_one_error_line(run_cli("info /no/such/scene.obj"));
    expect_one_error_line(run_cli("render /no/such/scene.obj -o /tmp/x.png"));
    expect_one_error_line(run_cli("info '" + test::data_path("cli/malformed.json") + "'"));
    expect_one_error_line(run_cli("info builtin:no_such_builtin"));
    std::string dir = test::temp_dir("cli_errors");
    expect_one_error_line(run_cli("render builtin:cornell --res 8x8 -o '" + dir + "/out.unknown'"));
    expect_one_error_line(run_cli("render builtin:cornell --res 8x8 -o '" + dir + "/missing/dir/out.png'"));
    // A camera looking nowhere is a runtime error too.
    expect_one_error_line(run_cli("render builtin:cornell --res 8x8 -o '" + dir + "/x.png' --camera 0,0,0,0,0,0,0,1,0,45"));
}

TEST(Cli, UsageErrorsExitTwo) {
    for (const char* args : {"", "bogus-verb", "render", "render builtin:cornell", "render builtin:cornell -o x.png --spp 0",
                             "render builtin:cornell -o x.png --res 640", "render builtin:cornell -o x.png --integrator bidir",
                             "render builtin:cornell -o x.png --light-sampling all", "render builtin:cornell -o x.png --tonemap filmic",
                             "render builtin:cornell -o x.png --aov speed",
                             "render builtin:cornell -o x.png --camera 1,2,3", "info builtin:cornell --no-such-flag",
                             "info", "info -v",
                             "render builtin:cornell -o x.png --device bogus",
                             "render builtin:cornell -o x.png --device cuda:x",
                             "render builtin:cornell -o x.png --gpu-kernel bogus",
                             "bench --device gpu", "bench --device cpu,bogus", "bench --gpu-kernel cwbvh,bogus",
                             "bench --spp 0"}) {
        CliResult r = run_cli(args);
        EXPECT_EQ(r.exit_code, 2) << "'" << args << "': " << r.err;
    }
}

TEST(Cli, BenchRunsTheProtocolAndWritesJson) {
    const std::string dir = test::temp_dir("cli_bench");
    const std::string json = dir + "/out.json";
    CliResult r = run_cli("bench --scene builtin:cube --layout bvh2 --res 32x24 --reps 1 --build-reps 1 --threads 2 -q --json '" +
                          json + "'");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("bvh/binned/bvh2"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("reflection"), std::string::npos) << r.out;
    std::ifstream in(json);
    const nlohmann::json root = nlohmann::json::parse(in);
    EXPECT_EQ(root["tool"], "rayforge bench");
    EXPECT_NE(root["command"].get<std::string>().find("--scene builtin:cube"), std::string::npos);
    ASSERT_EQ(root["records"].size(), 5u);
    for (const auto& rec : root["records"]) {
        EXPECT_EQ(rec["scene"], "builtin:cube");
        EXPECT_EQ(rec["builder"], "binned");
        EXPECT_GT(rec["rays"].get<size_t>(), 0u);
        EXPECT_GT(rec["mrays_per_s"].get<double>(), 0.0);
        EXPECT_TRUE(rec.contains("sah_cost") && rec.contains("quality_cost") && rec.contains("nodes_per_ray"));
    }
}

TEST(Cli, BenchListsEveryStructureAndRunsPresets) {
    CliResult list = run_cli("bench --list");
    ASSERT_EQ(list.exit_code, 0) << list.err;
    for (const char* label : {"zlatuska2009", "grid-proximity/uniform-64/grid", "kdtree/sah/pushdown", "bvh/sbvh/bvh8",
                              "bvh/binned+opt/bvh4", "bvh/gridbvh-split/bvh2"})
        EXPECT_NE(list.out.find(label), std::string::npos) << label;
    CliResult preset = run_cli("bench --preset bogolepov --scene builtin:cube --reps 1 --build-reps 1 -q --res 16x16");
    ASSERT_EQ(preset.exit_code, 0) << preset.err;
    EXPECT_NE(preset.out.find("grid-proximity/uniform-128/grid"), std::string::npos) << preset.out;
    EXPECT_NE(preset.out.find("PSR"), std::string::npos) << preset.out;
}

TEST(Cli, BenchErrorsAreOneLine) {
    expect_one_error_line(run_cli("bench --scene builtin:cube --builder binnned"));
    expect_one_error_line(run_cli("bench --scene builtin:cube --rays primaries"));
    expect_one_error_line(run_cli("bench --scene builtin:cube --res 0x10"));
    expect_one_error_line(run_cli("bench --scene /no/such/scene.obj"));
    expect_one_error_line(run_cli("bench --preset no-such-preset"));
    expect_one_error_line(run_cli("bench --scene builtin:cube --structure octree"));
    expect_one_error_line(run_cli("bench --scene builtin:cube --structure grid --builder binned"));
}

TEST(Cli, InfoDevicesSaysWhatThisBuildCanUse) {
    CliResult r = run_cli("info --devices");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.out.rfind("CUDA devices: ", 0), 0u) << r.out;
    if (!cuda_backend_built()) {
        EXPECT_NE(r.out.find("built without the CUDA backend"), std::string::npos) << r.out;
    } else if (r.out.find("CUDA devices: none") == std::string::npos) {
        // Each device: name, compute capability, memory, versions.
        for (const char* field : {"cuda:0", "compute capability", "SMs", "MiB total", "L2", "driver", "runtime"})
            EXPECT_NE(r.out.find(field), std::string::npos) << field << " missing in\n" << r.out;
    } else {
        EXPECT_NE(r.out.find("("), std::string::npos) << "the reason: " << r.out;
    }
    // With a scene, the devices and then the scene.
    CliResult both = run_cli("info --devices builtin:cube");
    ASSERT_EQ(both.exit_code, 0) << both.err;
    EXPECT_NE(both.out.find("CUDA devices: "), std::string::npos);
    EXPECT_NE(both.out.find("triangles:  12"), std::string::npos) << both.out;
}

TEST(Cli, RenderOnCudaNamesWhyItCannot) {
    const std::string out = test::temp_dir("cli_cuda") + "/x.png";
    CliResult r = run_cli("render builtin:cornell --res 16x16 -o '" + out + "' --device cuda --gpu-kernel grid -q");
    if (cuda_backend_built() && r.exit_code == 0) {
        // A device is present: the render ran there.
        EXPECT_TRUE(std::filesystem::exists(out));
        EXPECT_NE(r.out.find("cuda:0"), std::string::npos) << r.out;
        return;
    }
    expect_one_error_line(r);
    if (!cuda_backend_built()) {
        EXPECT_NE(r.err.find("--device cuda:0: this rayforge was built without the CUDA backend (nvcc was not found at "
                             "configure time)"),
                  std::string::npos)
            << r.err;
    } else {
        EXPECT_NE(r.err.find("--device cuda:0: "), std::string::npos) << r.err;
        EXPECT_EQ(r.err.find("built without"), std::string::npos) << r.err;
    }
    // Validated and then given up on before anything is written.
    EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(Cli, BuildReportsEveryBuildAndTheMedian) {
    CliResult r = run_cli("build builtin:cornell --builder hlbvh2 --reps 2 --threads 2");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("bvh/hlbvh2 on cpu, build 1:"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("bvh/hlbvh2 on cpu, build 2:"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("build 3:"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("median"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("SAH"), std::string::npos) << r.out;
    CliResult grid = run_cli("build builtin:cube --accel grid-proximity --reps 1");
    ASSERT_EQ(grid.exit_code, 0) << grid.err;
    EXPECT_NE(grid.out.find("on cpu, build 1:"), std::string::npos) << grid.out;
}

TEST(Cli, DeviceBuildOptionsNeedACudaDevice) {
    expect_one_error_line(run_cli("build builtin:cube --convert cwbvh"));
    expect_one_error_line(run_cli("render builtin:cube --res 8x8 -o /tmp/rf_never.png --build-on host"));
    CliResult bench = run_cli("bench --scene builtin:cube --res 8x8 --build-on device -q");
    expect_one_error_line(bench);
    EXPECT_NE(bench.err.find("--build-on: needs --device cuda"), std::string::npos) << bench.err;
    // A kd-tree has no device builder; without the backend the device itself is the error.
    CliResult kd = run_cli("build builtin:cube --accel kdtree --device cuda");
    expect_one_error_line(kd);
    EXPECT_NE(kd.err.find(cuda_backend_built() ? "--device cuda" : "built without the CUDA backend"),
              std::string::npos)
        << kd.err;
    for (const char* args : {"build", "build builtin:cube --reps 0", "build builtin:cube --convert bvh2",
                             "build builtin:cube --device gpu", "render builtin:cube -o x.png --build-on gpu"}) {
        CliResult usage = run_cli(args);
        EXPECT_EQ(usage.exit_code, 2) << "'" << args << "': " << usage.err;
    }
}

TEST(Cli, BenchBuildStagesWithoutAPreset) {
    CliResult r = run_cli("bench --scene builtin:cube --layout bvh2 --rays primary --res 8x8 --reps 1 --build-reps 1 "
                          "--embree none --threads 2 --build-stages -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("Build stages"), std::string::npos) << r.out;
    for (const char* builder : {"gridbvh", "gridbvh-split", "hlbvh2"})
        EXPECT_NE(r.out.find(std::string(" ") + builder + " "), std::string::npos) << builder << ": " << r.out;
}

TEST(Cli, RenderWavefrontWithSortedRaysOnTheCpu) {
    const std::string dir = test::temp_dir("cli_wavefront");
    CliResult r = run_cli("render builtin:cornell -o '" + dir + "/w.png' --res 32x32 --integrator path --spp 2 "
                          "--wavefront --sort-rays --device cpu --gpu-kernel cwbvh --threads 2 -q");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("path 2 spp"), std::string::npos) << r.out;
    EXPECT_EQ(read_image(dir + "/w.png").width, 32);
}

TEST(Cli, BenchOnCudaWithoutTheBackendIsOneError) {
    if (cuda_backend_built()) GTEST_SKIP() << "the CUDA backend is built";
    for (const char* args : {"bench --scene builtin:cube --device cuda --res 8x8 -q",
                             "bench --scene builtin:cube --device cpu,cuda:1 --res 8x8 -q",
                             "bench --scene builtin:cube --device cuda --integrator path --res 8x8 -q",
                             "bench --preset bogolepov --scene builtin:cube --device cuda -q"}) {
        CliResult r = run_cli(args);
        expect_one_error_line(r);
        EXPECT_NE(r.err.find("built without the CUDA backend"), std::string::npos) << args << ": " << r.err;
    }
    // --gpu-kernel asks for a device.
    expect_one_error_line(run_cli("bench --scene builtin:cube --gpu-kernel cwbvh --res 8x8 -q"));
}

TEST(Cli, BenchSppMultipliesTheCameraRays) {
    const std::string json = test::temp_dir("cli_bench_spp") + "/out.json";
    CliResult r = run_cli("bench --scene builtin:cube --layout bvh2 --rays primary --res 16x8 --spp 3 --reps 1 "
                          "--build-reps 1 --embree none --threads 2 -q --json '" + json + "'");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.out.find("cpu 3 (jittered)"), std::string::npos) << r.out;
    std::ifstream in(json);
    const nlohmann::json root = nlohmann::json::parse(in);
    ASSERT_EQ(root["records"].size(), 1u);
    EXPECT_EQ(root["records"][0]["rays"], 3u * 16u * 8u);
    EXPECT_EQ(root["records"][0]["samples_per_pixel"], 3);
    EXPECT_EQ(root["records"][0]["device"], "cpu");
    EXPECT_EQ(root["devices"], nlohmann::json::array({"cpu"}));
}

}  // namespace
}  // namespace rf
