// The rayforge verbs. Each registers its options on a CLI11 subcommand and
// runs from the parsed values; errors propagate as rf::Error to main().
#pragma once

#include <CLI/CLI.hpp>

#include <chrono>

#include "accel_options.h"
#include "device_options.h"
#include "paged_options.h"
#include "render_setup.h"

#include <string>
#include <vector>

namespace rf::cli {

inline constexpr const char* kVersion = RAYFORGE_VERSION;  // project(VERSION) in CMakeLists.txt

// When this process started (for the viewer's time to its first image).
std::chrono::steady_clock::time_point launch_time();

struct InfoArgs {
    std::string scene;  // a file or builtin:NAME (e.g. builtin:cornell); optional with --devices
    bool verbose = false;
    bool devices = false;  // list the CUDA devices
    std::string animation;  // --animation: the glTF clip to describe ("" = the first)
};
CLI::App* add_info_command(CLI::App& app, InfoArgs& args);
int run_info(const InfoArgs& args);

CLI::App* add_render_command(CLI::App& app, RenderArgs& args);
int run_render(const RenderArgs& args);

// Paged scenes (paged_commands.cpp): convert, generate, and the paged form of info.
struct ConvertArgs {
    std::string scene, output;
    std::string memory_budget = "1G";  // the streaming converter's working memory
    std::string temp_dir;              // its scratch files
    PagedWriteArgs write;
    int threads = 0;
    bool quiet = false;
};
CLI::App* add_convert_command(CLI::App& app, ConvertArgs& args);
int run_convert(const ConvertArgs& args);

struct GenerateArgs {
    std::string name, output, statues;
    std::string triangles = "4M";
    uint64_t seed = 1;
    std::string max_object = "2M";
    std::string instanced;  // forest: --instanced-triangles
    PagedWriteArgs write;
    int threads = 0;
    bool quiet = false;
};
CLI::App* add_generate_command(CLI::App& app, GenerateArgs& args);
int run_generate(const GenerateArgs& args);
int run_paged_info(const std::string& path, bool verbose);

// `rayforge view`: the render options plus the viewer's own.
struct ViewArgs {
    RenderArgs render;
    std::string script;         // --script FILE: commands run unattended
    std::string bookmarks;      // --bookmarks FILE (default: rayforge-bookmarks.json)
    std::string window;         // --window WxH ("" = the image size)
    std::string motion_scale = "auto";  // --motion-scale auto|N
    std::string scenes_dir;     // --scenes-dir: the views.json folder
    double script_timeout_s = 120.0;
};
CLI::App* add_view_command(CLI::App& app, ViewArgs& args);
int run_view(const ViewArgs& args);

struct BuildArgs {
    std::string scene;       // a file or builtin:NAME
    BuildOptions build;      // the structure, its builder and parameters, the device (--device), the threads
    int repetitions = 3;
    std::string convert;     // "", aila-laine or cwbvh: the device layout conversion too
};
CLI::App* add_build_command(CLI::App& app, BuildArgs& args);
int run_build(const BuildArgs& args);

struct BenchArgs {
    std::vector<std::string> scenes;       // comma lists allowed in every list option
    std::string scenes_dir;
    std::vector<std::string> views;
    std::vector<std::string> resolutions;
    std::vector<std::string> ray_sets;
    std::vector<std::string> structures;
    std::vector<std::string> builders;
    std::vector<std::string> layouts;
    std::vector<std::string> embree;
    std::string preset;
    int threads = 0;
    int repetitions = 5;
    int build_repetitions = 3;
    bool no_counts = false;
    std::string json;
    bool list = false;
    bool quiet = false;
    std::vector<std::string> integrators;  // render throughput instead of the ray sets
    int max_depth = 4;
    std::vector<std::string> devices;      // cpu, cuda, cuda:N (default cpu)
    std::vector<std::string> gpu_kernels;  // GPU kernel names or all (default: all, a preset's, or for
                                           // --integrator the default kernel)
    int spp = 0;                           // camera rays per pixel of the sets; 0 = 1 on the CPU, 4 on a GPU
    bool build_on_device = true;           // --build-on device|host for the GPU rows
    const CLI::Option* build_on = nullptr; //   (given or not)
    bool build_stages = false;             // the stage breakdown tables for every scene, not only garanzha2014's
    // --paged FILES: the paged-scene benchmark instead (bench/harness/paged_bench.h).
    std::vector<std::string> paged;        // .rfpack files
    std::vector<std::string> budgets;      // cache fractions of the scene, "0.01" or "1/100" ("" = Garanzha 2014's five)
    int passes = 4;                        // path-tracing passes per budget
    bool cold_from_disk = false;           // --paged: drop the file from the OS cache before each cold run
    std::string light_dir;                 // "x,y,z": a directional light for the shadow set
    // --animate: per-frame updates over an animation (bench/harness/animate_bench.h).
    bool animate = false;
    std::vector<std::string> updates;      // refit, adapt, rebuild, clusters, two-level ("" = all)
    std::string frames;                    // FIRST:LAST[:STEP] ("" = every frame)
    bool backwards = false;                // play FIRST..LAST, back to FIRST, forward to LAST
    long long ray_count = 1000000;         // diffuse rays per frame (0 = as the view gives)
    bool cluster_table = false;            // ch. 3's Table 3.1 instead
    int frame_reps = 1;                    // --animate: timed traces per set and frame (median)
    std::string adapt_reading;             // --animate: stated | closing (dM/dE of ch. 2; "" = stated)
};
CLI::App* add_bench_command(CLI::App& app, BenchArgs& args);
int run_bench(const BenchArgs& args, const std::string& command_line);

}  // namespace rf::cli
