// `rayforge bench`: every performance figure of the project comes from here
// (protocol: ../shared/docs/BENCHMARK-PROTOCOL.md, harness: bench/harness/).
// Tables on stdout, progress on stderr, records in --json FILE. `--device
// cuda` adds GPU rows (the same structures built and traced on the device).
// `--paged FILES` runs the paged-scene tables instead (bench/harness/paged_bench.h).
#include <iostream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "animate_bench.h"
#include "bench_report.h"
#include "bench_runner.h"
#include "commands.h"
#include "rayforge/world.h"
#include "paged_bench.h"
#include "presets.h"
#include "render_bench.h"
#include "stage_breakdown.h"
#include "rayforge/core/error.h"

namespace rf::cli {
namespace {

std::vector<std::string> split_list(const std::vector<std::string>& items) {
    std::vector<std::string> out;
    for (const std::string& item : items) {
        std::stringstream ss(item);
        std::string part;
        while (std::getline(ss, part, ','))
            if (!part.empty()) out.push_back(part);
    }
    return out;
}

bench::Resolution parse_resolution_or_throw(const std::string& text) {
    const size_t x = text.find_first_of("xX");
    try {
        size_t used_w = 0, used_h = 0;
        if (x == std::string::npos) throw Error("");
        const std::string w = text.substr(0, x), h = text.substr(x + 1);
        bench::Resolution r{std::stoi(w, &used_w), std::stoi(h, &used_h)};
        if (used_w != w.size() || used_h != h.size() || r.width <= 0 || r.height <= 0 || r.width > 16384 ||
            r.height > 16384)
            throw Error("");
        return r;
    } catch (const std::exception&) {
        throw Error("--res: expected WxH with sides in [1, 16384], got '" + text + "'");
    }
}

std::vector<bench::RaySetKind> parse_ray_sets(const std::vector<std::string>& names) {
    std::vector<bench::RaySetKind> kinds;
    for (const std::string& name : names) {
        if (name == "all") return {std::begin(bench::kAllRaySets), std::end(bench::kAllRaySets)};
        const auto kind = bench::parse_ray_set(name);
        if (!kind) throw Error("--rays: unknown ray set '" + name +
                                "' (primary, shadow, ao, diffuse, reflection, primary-morton, all)");
        kinds.push_back(*kind);
    }
    return kinds;
}

std::vector<bench::EmbreeQuality> parse_embree(const std::vector<std::string>& names) {
    std::vector<bench::EmbreeQuality> qualities;
    for (const std::string& name : names) {
        if (name == "none") return {};
        if (name == "all") return {std::begin(bench::kAllEmbreeQualities), std::end(bench::kAllEmbreeQualities)};
        bool found = false;
        for (bench::EmbreeQuality q : bench::kAllEmbreeQualities) {
            if (name != bench::embree_quality_name(q)) continue;
            qualities.push_back(q);
            found = true;
        }
        if (!found) throw Error("--embree: unknown quality '" + name + "' (low, medium, high, all, none)");
    }
    return qualities;
}

// --device: the CPU rows and at most one CUDA device.
struct DeviceSelection {
    bool cpu = false;
    bool gpu = false;
    int gpu_index = 0;
    std::string gpu_text;  // as given, for messages
};

DeviceSelection parse_devices(const std::vector<std::string>& names) {
    DeviceSelection selection;
    for (const std::string& name : names) {
        const Device device = parse_device(name);
        if (!device.is_cuda()) {
            selection.cpu = true;
            continue;
        }
        if (selection.gpu && selection.gpu_index != device.index)
            throw Error("--device: one CUDA device at a time (got cuda:" + std::to_string(selection.gpu_index) +
                        " and " + name + ")");
        selection.gpu = true;
        selection.gpu_index = device.index;
        selection.gpu_text = name;
    }
    return selection;
}

std::vector<GpuKernel> parse_gpu_kernels(const std::vector<std::string>& names) {
    std::vector<GpuKernel> kernels;
    for (const std::string& name : names) {
        if (name == "all") return all_gpu_kernels();
        kernels.push_back(parse_gpu_kernel(name));
    }
    return kernels;
}

void print_list(const std::string& scenes_dir) {
    std::cout << "scenes (views.json in " << (scenes_dir.empty() ? "<not found>" : scenes_dir) << "):\n";
    for (const std::string& name : bench::views_json_scene_names(scenes_dir)) std::cout << "  " << name << '\n';
    std::cout << "  builtin:sphereflake, builtin:terrain, builtin:instances, ... (rayforge info --help), or any "
                 "scene file\n  larger than a GPU's L2: NAME-xN (N copies of a views.json scene, e.g. dragon-x15), "
                 "generate:GENERATOR@COUNT[#SEED] (e.g. generate:terrain-statues@12M)\n\nstructure/builder/layout:\n";
    for (const bench::Candidate& c : bench::candidate_catalogue())
        std::cout << "  " << c.label() << (c.implemented ? "" : "  [not implemented yet]")
                  << (c.in_all ? "" : "  [only when named]") << "  (" << c.source << ")\n";
    std::cout << "\npresets:\n";
    for (const bench::Preset& p : bench::presets()) std::cout << "  " << p.name << ": " << p.description << '\n';
    std::cout << "\nembree peer: "
              << (bench::embree_available() ? "Embree " + bench::embree_version() : std::string("not built in"))
              << '\n';
    std::cout << "\nGPU kernels (--device cuda; CUDA backend " << (cuda_backend_built() ? "built" : "not built")
              << "):\n";
    for (GpuKernel kernel : all_gpu_kernels())
        std::cout << "  " << to_string(kernel) << "  (traces " << bench::gpu_kernel_structure(kernel) << ")\n";
}

// `--integrator`: rendering throughput of each scene's first view.
int run_render_bench(const BenchArgs& a, const bench::BenchConfig& config, const std::string& command_line) {
    bench::RenderBenchConfig render;
    render.cpu = config.cpu;
    if (!config.gpu.empty()) {
        // One renderer per kernel named; the default kernel unless --gpu-kernel says otherwise.
        const std::vector<GpuKernel> kernels =
            a.gpu_kernels.empty() ? std::vector<GpuKernel>{kDefaultGpuKernel} : parse_gpu_kernels(split_list(a.gpu_kernels));
        render.gpu = bench::gpu_candidates(kernels, config.candidates);
        const bool build_on_device = config.gpu.front().build.options.build_on_device;  // --build-on
        for (bench::GpuCandidate& g : render.gpu) g.build.options.build_on_device = build_on_device;
        render.gpu_device = config.gpu_device;
    }
    render.integrators = a.integrators;
    const bench::Resolution res = config.resolutions.empty() ? bench::Resolution{1024, 768} : config.resolutions.front();
    render.width = res.width;
    render.height = res.height;
    render.max_depth = a.max_depth;
    render.repetitions = a.repetitions;
    render.threads = a.threads;
    BuildOptions build = config.candidates.front().options;
    if (a.layouts.empty() && build.structure == Structure::Bvh) build.layout = BuildOptions{}.layout;
    render.build = build;
    std::vector<bench::RenderBenchRecord> records;
    for (const std::string& name : config.scenes) {
        const bench::LoadedScene scene = bench::load_bench_scene(bench::resolve_scene(name, config.scenes_dir));
        std::ostringstream sink;
        for (bench::RenderBenchRecord& r : bench::run_render_bench(scene, render, a.quiet ? sink : std::cerr))
            records.push_back(std::move(r));
    }
    bench::print_render_table(std::cout, records);
    if (!a.json.empty()) {
        bench::write_render_json(a.json, records, command_line);
        std::cout << "\nwrote " << records.size() << " records to " << a.json << '\n';
    }
    return 0;
}

// "0.01", "1/100" -> 0.01; a fraction of the scene in (0, 1].
double parse_budget(const std::string& text) {
    try {
        size_t used = 0;
        const size_t slash = text.find('/');
        double value = std::stod(text.substr(0, slash), &used);
        if (used != (slash == std::string::npos ? text.size() : slash)) throw Error("");
        if (slash != std::string::npos) {
            const std::string denominator = text.substr(slash + 1);
            value /= std::stod(denominator, &used);
            if (used != denominator.size()) throw Error("");
        }
        if (!(value > 0.0 && value <= 1.0)) throw Error("");
        return value;
    } catch (const std::exception&) {
        throw Error("--budgets: expected fractions of the scene in (0, 1] such as 0.1 or 1/200, got '" + text + "'");
    }
}

// "x,y,z" -> a directional light travelling along it.
Light parse_light_dir(const std::string& text) {
    std::vector<float> values;
    for (const std::string& part : split_list({text})) {
        try {
            size_t used = 0;
            values.push_back(std::stof(part, &used));
            if (used != part.size()) throw Error("");
        } catch (const std::exception&) {
            values.clear();
            break;
        }
    }
    const Vec3f dir = values.size() == 3 ? Vec3f{values[0], values[1], values[2]} : Vec3f(0.0f);
    if (!(length(dir) > 0.0f) || !is_finite(dir))
        throw Error("--light-dir: expected three numbers x,y,z, not all zero, got '" + text + "'");
    Light light;
    light.type = LightType::Directional;
    light.direction = normalize(dir);
    return light;
}

// `--paged`: the paged-scene tables (bench/harness/paged_bench.h), one file at a time.
int run_paged_bench_command(const BenchArgs& a, const std::string& command_line) {
    if (!a.scenes.empty() || !a.preset.empty() || !a.integrators.empty() || !a.ray_sets.empty() ||
        !a.structures.empty() || !a.builders.empty() || !a.layouts.empty() || !a.devices.empty())
        throw Error("--paged: not with --scene, --preset, --integrator, --rays, --structure, --builder, --layout or "
                    "--device (the paged bench has its own workloads)");
    bench::PagedBenchConfig config;
    const std::vector<std::string> budgets = split_list(a.budgets);
    if (!budgets.empty()) {
        config.budgets.clear();
        for (const std::string& b : budgets) config.budgets.push_back(parse_budget(b));
    }
    const std::vector<std::string> resolutions = split_list(a.resolutions);
    if (!resolutions.empty()) {
        const bench::Resolution res = parse_resolution_or_throw(resolutions.front());
        config.width = res.width;
        config.height = res.height;
    }
    config.repetitions = a.repetitions;
    config.passes = a.passes;
    config.cold_from_disk = a.cold_from_disk;
    config.threads = a.threads;
    if (!a.light_dir.empty()) config.light = parse_light_dir(a.light_dir);
    const std::vector<std::string> files = split_list(a.paged);
    for (const std::string& file : files)
        if (!is_paged_scene_file(file))
            throw Error(file + ": not a paged scene file (rayforge convert or rayforge generate writes one)");
    bench::print_paged_header(std::cout, config, command_line);
    if (resolutions.size() > 1) std::cout << "note: --paged uses the first --res only\n";
    std::vector<bench::PagedFileResult> results;
    std::ostringstream sink;
    for (const std::string& file : files) {
        results.push_back(bench::run_paged_bench(file, config, a.quiet ? sink : std::cerr));
        bench::print_paged_tables(std::cout, results.back(), config);
    }
    if (!a.json.empty()) {
        bench::write_paged_json(a.json, results, config, command_line);
        std::cout << "\nwrote the records of " << results.size() << " files to " << a.json << '\n';
    }
    return 0;
}

// --embree under --animate: the dynamic peer's modes.
std::vector<bench::EmbreeUpdate> parse_embree_updates(const std::vector<std::string>& names) {
    std::vector<bench::EmbreeUpdate> updates;
    for (const std::string& name : names) {
        if (name == "none") return {};
        if (name == "all") return {std::begin(bench::kAllEmbreeUpdates), std::end(bench::kAllEmbreeUpdates)};
        bool found = false;
        for (bench::EmbreeUpdate u : bench::kAllEmbreeUpdates) {
            if (name != bench::embree_update_name(u)) continue;
            updates.push_back(u);
            found = true;
        }
        if (!found) throw Error("--embree: with --animate, one of refit, low, medium, all, none (got '" + name + "')");
    }
    return updates;
}

// The one builder and layout of --animate and --cluster-table (first of --builder / --layout).
BuildOptions animate_build(const BenchArgs& a) {
    BuildOptions build;
    const std::vector<std::string> builders = split_list(a.builders), layouts = split_list(a.layouts);
    if (!builders.empty()) build.builder = parse_builder(builders.front());
    if (!layouts.empty()) build.layout = parse_layout(layouts.front());
    build.threads = a.threads;
    return build;
}

std::vector<bench::LoadedScene> load_animate_scenes(const BenchArgs& a, const std::string& scenes_dir) {
    std::vector<std::string> names = split_list(a.scenes);
    if (names.empty()) names = {"builtin:explode", "builtin:cloth", "builtin:nbody"};
    std::vector<bench::LoadedScene> scenes;
    for (const std::string& name : names) {
        if (!a.quiet) std::cerr << "loading " << name << '\n';
        scenes.push_back(bench::load_bench_scene(bench::resolve_scene(name, scenes_dir)));
    }
    return scenes;
}

// `--cluster-table`: ch. 3's Table 3.1 on each scene (frame 0 of an animated one).
int run_cluster_table_command(const BenchArgs& a, const std::string& scenes_dir) {
    bench::ClusterTableConfig config;
    config.build = animate_build(a);
    config.threads = a.threads;
    config.repetitions = a.build_repetitions;
    config.progress = !a.quiet;
    const std::vector<std::string> resolutions = split_list(a.resolutions);
    if (!resolutions.empty()) {
        const bench::Resolution res = parse_resolution_or_throw(resolutions.front());
        config.width = res.width;
        config.height = res.height;
    }
    std::vector<bench::ClusterTable> tables;
    std::ostringstream sink;
    for (bench::LoadedScene& scene : load_animate_scenes(a, scenes_dir))
        tables.push_back(bench::run_cluster_table(scene, config, a.quiet ? sink : std::cerr));
    bench::print_cluster_tables(std::cout, tables, a.threads > 0 ? a.threads : bench::machine_info().cores);
    return 0;
}

// `--animate`: per-frame updates of every method against a rebuild and Embree (bench/harness/animate_bench.h).
int run_animate_command(const BenchArgs& a, const std::string& command_line, const std::string& scenes_dir) {
    if (!a.paged.empty() || !a.integrators.empty() || !a.preset.empty() || !a.gpu_kernels.empty())
        throw Error("--animate, --cluster-table: not with --paged, --integrator, --preset or --gpu-kernel");
    const std::vector<std::string> devices = split_list(a.devices);
    if (devices.size() > 1) throw Error("--animate, --cluster-table: one --device at a time");
    const Device device = devices.empty() ? Device{} : parse_device(devices.front());
    require_usable(device);
    if (a.cluster_table) {  // the clusters' updater, which the library refuses on a device that cannot run it
        WorldOptions clusters;
        clusters.device = device;
        clusters.update.method = UpdateMethod::Clusters;
        check_world_options(clusters);
        return run_cluster_table_command(a, scenes_dir);
    }
    bench::AnimateConfig config;
    config.device = device;
    config.build = animate_build(a);
    const std::vector<std::string> updates = split_list(a.updates);
    if (!updates.empty() && updates.front() != "all") {
        config.methods.clear();
        for (const std::string& u : updates) config.methods.push_back(parse_update_method(u));
    }
    if (!a.adapt_reading.empty()) config.update.adapt = parse_adapt_reading(a.adapt_reading);
    if (!a.frames.empty()) config.frames = bench::parse_frame_range(a.frames);
    config.backwards = a.backwards;
    if (!a.ray_sets.empty()) config.ray_sets = parse_ray_sets(split_list(a.ray_sets));
    const std::vector<std::string> resolutions = split_list(a.resolutions);
    if (!resolutions.empty()) {
        const bench::Resolution res = parse_resolution_or_throw(resolutions.front());
        config.width = res.width;
        config.height = res.height;
    }
    if (a.ray_count < 0) throw Error("--ray-count: expected a count >= 0");
    config.diffuse_rays = size_t(a.ray_count);
    config.embree = a.embree.empty() ? std::vector<bench::EmbreeUpdate>{std::begin(bench::kAllEmbreeUpdates),
                                                                         std::end(bench::kAllEmbreeUpdates)}
                                     : parse_embree_updates(split_list(a.embree));
    if (!bench::embree_available()) {
        if (!a.embree.empty() && !config.embree.empty())
            throw Error("--embree: this rayforge was built without Embree (Debian: libembree-dev)");
        if (!config.embree.empty()) std::cout << "note: built without Embree; no peer columns\n";
        config.embree.clear();
    }
    config.threads = a.threads;
    config.repetitions = a.frame_reps;
    config.progress = !a.quiet;
    std::vector<bench::AnimateResult> results;
    std::ostringstream sink;
    for (bench::LoadedScene& scene : load_animate_scenes(a, scenes_dir)) {
        results.push_back(bench::run_animate_bench(scene, config, a.quiet ? sink : std::cerr));
        bench::print_animate_tables(std::cout, results.back());
    }
    if (!a.json.empty()) {
        bench::write_animate_json(a.json, results, command_line);
        std::cout << "\nwrote the frames of " << results.size() << " scenes to " << a.json << '\n';
    }
    return 0;
}

}  // namespace

// Without --builder: the default BVH builder, and every "builder" of the
// other structures (grid resolutions, the kd-tree's SAH).
static std::vector<std::string> default_builders() {
    std::set<std::string> names{to_string(BuildOptions{}.builder)};
    for (const bench::Candidate& c : bench::candidate_catalogue())
        if (c.structure != "bvh") names.insert(c.builder);
    return {names.begin(), names.end()};
}

CLI::App* add_bench_command(CLI::App& app, BenchArgs& a) {
    CLI::App* cmd = app.add_subcommand(
        "bench", "Benchmark structures and builders on the standard ray sets, with Embree side by side");
    cmd->add_option("--scene", a.scenes,
                    "Scenes: views.json names (e.g. sponza), files, builtin:NAME, NAME-xN (N copies of a views.json "
                    "scene, e.g. dragon-x15), generate:GENERATOR@COUNT[#SEED] (e.g. generate:terrain-statues@12M), "
                    "or all; comma-separated or repeated (default: sponza,conference,bunny, or three builtin scenes "
                    "without ../shared)");
    cmd->add_option("--scenes-dir", a.scenes_dir,
                    "Folder with views.json (default: $RAYFORGE_SCENES_DIR, else shared/scenes found upwards)");
    cmd->add_option("--view", a.views, "View indices of views.json, comma-separated, or all (default all)");
    cmd->add_option("--res", a.resolutions, "Image sizes WxH, comma-separated (default 1024x768)");
    cmd->add_option("--rays", a.ray_sets,
                    "Ray sets: primary, shadow, ao, diffuse, reflection, all (the protocol's five; default all), "
                    "primary-morton (the primaries in Morton order of their pixels; GPU rows trace it beside "
                    "every primary set)");
    cmd->add_option("--structure", a.structures, "Structures, or all (default bvh; brute only when named)");
    cmd->add_option("--builder", a.builders, "Builders, or all (default: the default builder, binned)");
    cmd->add_option("--layout", a.layouts, "Layouts, or all (default all)");
    cmd->add_option("--embree", a.embree, "Embree peer build qualities: low, medium, high, all, none (default all)");
    cmd->add_option("--preset", a.preset,
                    "bogolepov | zlatuska2009 | garanzha2014: reproduce a paper's tables (see --list)");
    cmd->add_option("--threads", a.threads, "Threads for builds and traces (0 = all cores)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--reps", a.repetitions, "Timed traces per ray set, after one warm-up (default 5)")
        ->check(CLI::Range(1, 1000));
    cmd->add_option("--build-reps", a.build_repetitions, "Builds per structure (default 3)")
        ->check(CLI::Range(1, 1000));
    cmd->add_flag("--no-counts", a.no_counts, "Skip the instrumented pass (node visits and tests per ray)");
    cmd->add_option("--json", a.json, "Write one JSON record per (scene, structure, builder, layout, ray set)");
    cmd->add_option("--integrator", a.integrators,
                    "Measure rendering instead of the ray sets: normals, ao, whitted, path (comma list): passes/s, "
                    "samples/s and rays/s of all bounces next to the same rays traced without shading. Uses the "
                    "first --structure/--builder/--layout combination (default bvh/binned/bvh8), --res (first), "
                    "--reps, --threads; view 0 of each scene")
        ->check(CLI::IsMember({"normals", "ao", "whitted", "path"}))
        ->delimiter(',');
    cmd->add_option("--max-depth", a.max_depth, "Path bounces for --integrator path (default 4)")
        ->check(CLI::Range(0, 1024));
    cmd->add_option("--device", a.devices,
                    "Where to trace: cpu, cuda (= cuda:0), cuda:N, comma-separated (default cpu); cuda adds one row "
                    "per GPU kernel, on its own ray sets (--spp)")
        ->delimiter(',')
        ->check(device_validator());
    cmd->add_option("--gpu-kernel", a.gpu_kernels,
                    "GPU kernels for --device cuda: bvh2, aila-laine, aila-laine-fma, cwbvh, cwbvh-fma, kd-short-stack, kd-restart, grid, "
                    "grid-proximity, or all (default all; a preset's for its structures; with --integrator " +
                        to_string(kDefaultGpuKernel) + ")")
        ->delimiter(',')
        ->check(gpu_kernel_validator(true));
    cmd->add_option("--spp", a.spp,
                    "Camera rays per pixel of the ray sets, sample 0 at the pixel centre and the others jittered "
                    "(default: 1 for cpu rows, 4 for cuda rows, the protocol's GPU rule)")
        ->check(CLI::Range(1, 64));
    a.build_on = add_build_on_option(cmd, a.build_on_device);
    cmd->add_flag("--build-stages", a.build_stages,
                  "After the tables, time every builder stage by stage on each scene (dissertation tables 4.1 and "
                  "5.1: the CPU's gridbvh, gridbvh-split and hlbvh2; with --device cuda every device builder, the "
                  "device uniform grids and the device layout conversions), as the garanzha2014 preset does");
    cmd->add_option("--paged", a.paged,
                    "Paged scene files (.rfpack), comma-separated: instead of the ray-set tables, trace each at every "
                    "--budgets cache size (primary, shadow, 3 diffuse bounces, path tracing) against the same "
                    "geometry in core (docs/cli.md, Paged scenes). Uses --res (first; default 1024x768), --reps, "
                    "--passes, --threads, --json")
        ->delimiter(',');
    cmd->add_option("--budgets", a.budgets,
                    "--paged: cache sizes as fractions of the scene, e.g. 0.1 or 1/200, comma-separated (default "
                    "1,0.5,0.1,0.01,0.005)")
        ->delimiter(',');
    cmd->add_option("--passes", a.passes, "--paged: path-tracing passes per budget, the first one cold (default 4)")
        ->check(CLI::Range(2, 10000));
    cmd->add_flag("--cold-from-disk", a.cold_from_disk,
                  "--paged: before each cold run also drop the file from the operating system's cache "
                  "(posix_fadvise), so cold runs read the disk");
    cmd->add_option("--light-dir", a.light_dir,
                    "--paged: the shadow set's light, a directional light travelling along x,y,z (default: the file's "
                    "first light, when the API lists it)");
    cmd->add_flag("--animate", a.animate,
                  "Per-frame acceleration updates over each scene's animation (default scenes builtin:explode, "
                  "builtin:cloth, builtin:nbody): every --update method against a full rebuild of the same frame "
                  "(first --builder/--layout) and the Embree peer (--embree refit,low,medium), on the frame's "
                  "--rays (default primary,shadow,diffuse; --res view, default 512x384); docs/cli.md");
    cmd->add_option("--update", a.updates, "--animate: refit, adapt, rebuild, clusters, two-level, or all (default all)")
        ->delimiter(',');
    cmd->add_option("--frames", a.frames, "--animate: FIRST:LAST[:STEP] (default every frame; built at FIRST)");
    cmd->add_flag("--backwards", a.backwards,
                  "--animate: play FIRST..LAST, back to FIRST and forward to LAST again (Garanzha 2014's 100-1-100)");
    cmd->add_option("--ray-count", a.ray_count, "--animate: diffuse rays per frame (default 1000000; 0 = the --res view's)");
    cmd->add_option("--frame-reps", a.frame_reps, "--animate: timed traces per set and frame, median (default 1)")
        ->check(CLI::Range(1, 100));
    cmd->add_option("--adapt-reading", a.adapt_reading,
                    "--animate: adapt's thresholds, stated (dM 0.05, dE 0.01; default) or closing (dM 0.01, dE 0.05)");
    cmd->add_flag("--cluster-table", a.cluster_table,
                  "Garanzha ch. 3 Table 3.1 on each scene: MaxCount=MaxSize 0,10,50,100,200 with the Acc and Naive "
                  "heuristics: clustering ms, clusters, build ms, primary and diffuse trace ms (--build-reps runs)");
    cmd->add_flag("--list", a.list, "List scenes, structures, presets and the Embree peer, then exit");
    cmd->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");
    return cmd;
}

namespace {

// The candidates (a preset's, or --structure/--builder/--layout) and the scenes to run.
const bench::Preset* choose_work(const BenchArgs& a, bench::BenchConfig& config, bench::RunInfo& info) {
    std::vector<bench::Candidate> unimplemented;
    std::vector<std::string> scenes = split_list(a.scenes);
    const bench::Preset* preset = nullptr;
    if (!a.preset.empty()) {
        preset = &bench::find_preset(a.preset);
        info.preset = preset->name;
        info.notes = preset->notes;
        config.candidates = bench::candidates_by_label(preset->candidates, &unimplemented);
        config.resolutions = preset->resolutions;
        config.ray_sets = preset->ray_sets;
        if (scenes.empty()) {
            scenes = config.scenes_dir.empty() ? preset->fallback_scenes : preset->scenes;
            config.skip_unloadable = true;  // a preset's scene missing from this checkout of ../shared
        }
    } else {
        config.candidates = bench::select_candidates(
            a.structures.empty() ? std::vector<std::string>{"bvh"} : split_list(a.structures),
            a.builders.empty() ? default_builders() : split_list(a.builders),
            a.layouts.empty() ? std::vector<std::string>{"all"} : split_list(a.layouts), &unimplemented);
    }
    if (scenes.empty()) scenes = bench::default_scene_names(config.scenes_dir);
    if (scenes.size() == 1 && scenes.front() == "all") {
        scenes = bench::views_json_scene_names(config.scenes_dir);
        if (scenes.empty()) throw Error("--scene all: no views.json found (give --scenes-dir)");
        config.skip_unloadable = true;
    }
    config.scenes = scenes;
    for (const bench::Candidate& c : unimplemented) info.unimplemented.push_back(c.label());
    return preset;
}

// --res, --rays and --view.
void choose_views(const BenchArgs& a, bench::BenchConfig& config) {
    if (!a.resolutions.empty()) {
        config.resolutions.clear();
        for (const std::string& r : split_list(a.resolutions)) config.resolutions.push_back(parse_resolution_or_throw(r));
    }
    if (!a.ray_sets.empty()) config.ray_sets = parse_ray_sets(split_list(a.ray_sets));
    for (const std::string& v : split_list(a.views)) {
        if (v == "all") {
            config.views.clear();
            break;
        }
        try {
            size_t used = 0;
            const int index = std::stoi(v, &used);
            if (used != v.size() || index < 0) throw Error("");
            config.views.push_back(index);
        } catch (const std::exception&) {
            throw Error("--view: expected view indices or all, got '" + v + "'");
        }
    }
}

// The rows: CPU with the Embree peer, and the GPU kernels on one device.
void choose_devices(const BenchArgs& a, const DeviceSelection& devices, const bench::Preset* preset,
                    bench::BenchConfig& config, bench::RunInfo& info) {
    if (a.build_on->count() > 0 && !devices.gpu) throw Error("--build-on: needs --device cuda");
    const bool build_on_device = a.build_on_device;
    const std::vector<std::string> embree_names = a.embree.empty() ? std::vector<std::string>{"all"} : split_list(a.embree);
    config.embree = parse_embree(embree_names);
    if (!devices.cpu) config.embree.clear();  // the peer is a CPU column
    if (!config.embree.empty() && !bench::embree_available()) {
        if (!a.embree.empty()) throw Error("--embree: this rayforge was built without Embree (Debian: libembree-dev)");
        info.notes.push_back("built without Embree; no peer columns (Debian: apt-get install libembree-dev)");
        config.embree.clear();
    }
    config.cpu = devices.cpu;
    if (devices.gpu) {
        const std::vector<GpuKernel> kernels = !a.gpu_kernels.empty() ? parse_gpu_kernels(split_list(a.gpu_kernels))
                                               : preset                ? preset->gpu_kernels
                                                                       : all_gpu_kernels();
        config.gpu = bench::gpu_candidates(kernels, config.candidates);
        for (bench::GpuCandidate& g : config.gpu) g.build.options.build_on_device = build_on_device;
        config.gpu_device = devices.gpu_index;
        info.gpu = bench::gpu_device_name(devices.gpu_index);
    }
    config.cpu_samples_per_pixel = a.spp > 0 ? a.spp : 1;
    config.gpu_samples_per_pixel = a.spp > 0 ? a.spp : 4;
    info.devices.clear();
    if (devices.cpu) info.devices.push_back("cpu");
    if (devices.gpu) info.devices.push_back("cuda:" + std::to_string(devices.gpu_index));
}

// Notes go to stdout (and the JSON): stderr carries progress and at most one error line.
void print_notes(const BenchArgs& a, const DeviceSelection& devices, const bench::Preset* preset,
                 bench::RunInfo& info) {
    if (a.repetitions < 5)
        info.notes.push_back("--reps " + std::to_string(a.repetitions) + " is below the protocol's 5 timed runs");
    if (devices.gpu && a.spp > 0 && a.spp < 4)
        info.notes.push_back("--spp " + std::to_string(a.spp) +
                             " is below the protocol's 4 jittered samples per pixel for GPU sets");
    if (a.build_repetitions < 3)
        info.notes.push_back("--build-reps " + std::to_string(a.build_repetitions) + " is below the protocol's 3 builds");
    if (preset) std::cout << "preset " << preset->name << ": " << preset->description << '\n';
    for (const std::string& note : info.notes) std::cout << "note: " << note << '\n';
    if (!info.unimplemented.empty()) {
        std::cout << "not implemented yet (skipped):";
        for (const std::string& label : info.unimplemented) std::cout << ' ' << label;
        std::cout << '\n';
    }
}

// Every builder stage by stage on each scene, after the tables.
void run_stage_breakdowns(const BenchArgs& a, const DeviceSelection& devices, const bench::BenchConfig& config) {
    std::vector<bench::StageBreakdown> stages;
    for (const std::string& name : config.scenes) {
        bench::LoadedScene scene;
        try {
            scene = bench::load_bench_scene(bench::resolve_scene(name, config.scenes_dir));
        } catch (const Error&) {
            continue;  // unloadable scenes were reported by the main run
        }
        if (!a.quiet) std::cerr << "stage breakdown: " << scene.spec.name << '\n';
        if (devices.cpu)
            for (bench::StageBreakdown& row : bench::measure_stage_breakdowns(scene, a.threads, a.build_repetitions))
                stages.push_back(std::move(row));
        if (devices.gpu)  // device failures are errors: the device was asked for
            for (bench::StageBreakdown& row :
                 bench::measure_device_stage_breakdowns(scene, devices.gpu_index, a.build_repetitions))
                stages.push_back(std::move(row));
    }
    bench::print_stage_breakdowns(std::cout, stages, a.threads, a.build_repetitions);
}

}  // namespace

int run_bench(const BenchArgs& a, const std::string& command_line) {
    if (!a.paged.empty()) return run_paged_bench_command(a, command_line);
    if (!a.budgets.empty() || !a.light_dir.empty()) throw Error("--budgets and --light-dir: need --paged");
    bench::BenchConfig config;
    config.scenes_dir = bench::find_scenes_dir(a.scenes_dir);
    if (a.list) {
        print_list(config.scenes_dir);
        return 0;
    }
    if (a.animate || a.cluster_table) return run_animate_command(a, command_line, config.scenes_dir);
    bench::RunInfo info;
    info.command = command_line;
    const DeviceSelection devices = parse_devices(a.devices.empty() ? std::vector<std::string>{"cpu"}
                                                                    : split_list(a.devices));
    if (devices.gpu) require_usable(Device{Device::Kind::Cuda, devices.gpu_index});
    if (!devices.gpu && !a.gpu_kernels.empty()) throw Error("--gpu-kernel: needs --device cuda");
    const bench::Preset* preset = choose_work(a, config, info);
    choose_views(a, config);
    choose_devices(a, devices, preset, config, info);
    config.threads = a.threads;
    config.repetitions = a.repetitions;
    config.build_repetitions = a.build_repetitions;
    config.count_traversal = !a.no_counts;
    config.progress = !a.quiet;
    info.threads = a.threads;
    info.repetitions = a.repetitions;
    info.build_repetitions = a.build_repetitions;
    print_notes(a, devices, preset, info);
    if (config.candidates.empty())
        throw Error("nothing to run: no implemented combination matches --structure, --builder and --layout "
                    "(see --list)");
    if (!a.integrators.empty()) return run_render_bench(a, config, command_line);

    const std::vector<bench::BenchRecord> records =
        bench::run_bench(config, std::cerr, [&](const std::vector<bench::BenchRecord>& scene_records) {
            bench::print_scene_tables(std::cout, scene_records, a.threads > 0 ? a.threads : bench::machine_info().cores,
                                      a.repetitions, a.build_repetitions);
        });
    if (preset && preset->configuration_table) bench::print_configuration_table(std::cout, records);
    if ((preset && preset->stage_breakdown) || a.build_stages) run_stage_breakdowns(a, devices, config);
    if (!a.json.empty()) {
        bench::write_json(a.json, records, info);
        std::cout << "\nwrote " << records.size() << " records to " << a.json << '\n';
    }
    if (records.empty()) throw Error("no scene could be benchmarked");
    return 0;
}

}  // namespace rf::cli
