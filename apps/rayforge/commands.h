// The rayforge verbs. Each registers its options on a CLI11 subcommand and
// runs from the parsed values; errors propagate as rf::Error to main().
#pragma once

#include <CLI/CLI.hpp>

#include "accel_options.h"
#include "device_options.h"

#include <string>
#include <vector>

namespace rf::cli {

inline constexpr const char* kVersion = RAYFORGE_VERSION;  // project(VERSION) in CMakeLists.txt

struct InfoArgs {
    std::string scene;  // a file or builtin:NAME (e.g. builtin:cornell); optional with --devices
    bool verbose = false;
    bool devices = false;  // list the CUDA devices
};
CLI::App* add_info_command(CLI::App& app, InfoArgs& args);
int run_info(const InfoArgs& args);

struct RenderArgs {
    std::string scene;  // a file or builtin:NAME (e.g. builtin:cornell)
    std::vector<std::string> outputs;  // one or more images; the format follows each extension
    std::string resolution;   // "WxH"
    int spp = 1;
    std::string integrator;
    std::string camera;       // "ex,ey,ez,tx,ty,tz,ux,uy,uz,fov"
    int threads = 0;
    int max_depth = 8;
    int rr_depth = 3;
    std::string light_sampling = "mis";
    float clamp = 0.0f;
    int reflection_depth = 1;
    int refraction_depth = 2;
    std::string shading = "lambert";
    double time_budget_s = 0.0;
    int save_every = 0;       // write the outputs every N passes (0 = only at the end)
    float ao_radius = 0.0f;
    int ao_samples = 16;
    float exposure = 1.0f;
    std::string tonemap = "clamp";
    std::vector<std::string> aovs;    // albedo, normal, depth
    unsigned seed = 0;
    AccelArgs accel;
    std::vector<std::string> lights;  // "x,y,z[,intensity]" point lights added to the scene
    std::string environment;          // "r,g,b" constant environment radiance
    std::string environment_map;      // an equirectangular image, or builtin:sky
    float environment_strength = 1.0f;
    bool no_headlight = false;
    bool quiet = false;
    std::string device = "cpu";       // cpu | cuda | cuda:N
    std::string gpu_kernel;           // "" = rf::kDefaultGpuKernel
    std::string build_on;             // --build-on device|host ("" = device), with --device cuda
    bool wavefront = false;           // CPU path tracer: wavefront passes
    bool sort_rays = false;           // CPU wavefront: sort rays before tracing
    // Options whose presence overrides the scene file's render settings.
    CLI::Option* resolution_opt = nullptr;
    CLI::Option* spp_opt = nullptr;
    CLI::Option* integrator_opt = nullptr;
    CLI::Option* max_depth_opt = nullptr;
    CLI::Option* ao_radius_opt = nullptr;
    CLI::Option* environment_strength_opt = nullptr;
    CLI::Option* rr_depth_opt = nullptr;
    CLI::Option* light_sampling_opt = nullptr;
    CLI::Option* reflection_depth_opt = nullptr;
    CLI::Option* refraction_depth_opt = nullptr;
    CLI::Option* shading_opt = nullptr;
};
CLI::App* add_render_command(CLI::App& app, RenderArgs& args);
int run_render(const RenderArgs& args);

struct BuildArgs {
    std::string scene;       // a file or builtin:NAME
    AccelArgs accel;
    std::string device = "cpu";
    int repetitions = 3;
    int threads = 0;
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
    std::string build_on;                  // --build-on device|host ("" = device) for the GPU rows
    bool build_stages = false;             // the stage breakdown tables for every scene, not only seed000's
};
CLI::App* add_bench_command(CLI::App& app, BenchArgs& args);
int run_bench(const BenchArgs& args, const std::string& command_line);

}  // namespace rf::cli
