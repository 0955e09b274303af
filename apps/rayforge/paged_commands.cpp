// The paged-scene verbs (docs/paged-scenes.md): `convert` writes a scene as
// a paged file, `generate` writes a procedural one; `info` of a paged file
// comes here from its command (`render` and `view` open paged files as
// worlds, like any scene).
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>

#include "commands.h"
#include "elapsed.h"
#include "paged_options.h"
#include "progress_bar.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"
#include "rayforge/io/image_io.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"

namespace rf::cli {

namespace {

using Clock = std::chrono::steady_clock;

void print_write_report(const std::string& path, const PagedWriteReport& r, double ms) {
    if (r.geometry_pages == 0) {  // `generate` into an OBJ file: no pages
        std::printf("%s: %llu triangles, %s written in %.1f s (%.2f Mtriangles/s)\n", path.c_str(),
                    (unsigned long long)r.triangles, format_bytes(double(r.file_bytes)).c_str(), ms / 1e3,
                    ms > 0.0 ? double(r.triangles) / (ms * 1e3) : 0.0);
        for (const std::string& note : r.notes) std::printf("%s: note: %s\n", path.c_str(), note.c_str());
        return;
    }
    const std::string placed =
        r.instances == 0 ? std::string()
                         : " (+ " + std::to_string(r.instances) + " instances placing " +
                               std::to_string(r.instanced_triangles) + " more)";
    std::printf("%s: %llu unique triangles%s -> %llu quads (%.1f%% paired) in %u geometry, %u attribute, %u texture "
                "pages | %s (geometry %s, attributes %s, textures %s, resident %s; %s decoded), %.1f bytes a unique "
                "triangle | max quantisation error %.3g | %.1f s (%.2f Mtriangles/s)\n",
                path.c_str(), (unsigned long long)r.triangles, placed.c_str(), (unsigned long long)r.quads,
                r.triangles ? 100.0 * double(r.paired_triangles) / double(r.triangles) : 0.0, r.geometry_pages,
                r.attribute_pages, r.texture_pages, format_bytes(double(r.file_bytes)).c_str(),
                format_bytes(double(r.geometry_bytes)).c_str(), format_bytes(double(r.attribute_bytes)).c_str(),
                format_bytes(double(r.texture_bytes)).c_str(), format_bytes(double(r.resident_bytes)).c_str(),
                format_bytes(double(r.decoded_bytes)).c_str(), r.bytes_per_triangle(), r.max_quantisation_error, ms / 1e3, ms > 0.0 ? double(r.triangles) / (ms * 1e3) : 0.0);
    for (const std::string& note : r.notes) std::printf("%s: note: %s\n", path.c_str(), note.c_str());
}

// The process's peak resident set (the kernel's high-water mark).
double peak_resident_bytes() {
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    return double(usage.ru_maxrss) * 1024.0;  // kilobytes on Linux
}

}  // namespace

CLI::App* add_convert_command(CLI::App& app, ConvertArgs& a) {
    CLI::App* cmd = app.add_subcommand("convert", "Write a scene as a paged scene file (.rfpack) for out-of-core rendering");
    cmd->add_option("scene", a.scene, "Scene file (.obj, .gltf, .glb, .ply, .aff, .json) or builtin:NAME")->required();
    cmd->add_option("-o,--output", a.output, "The paged scene file to write (.rfpack)")->required();
    cmd->add_option("--memory-budget", a.memory_budget,
                    "Working memory when streaming an .obj input, e.g. 512M, 4G (default 1G, at least 96M); other "
                    "formats are loaded in core");
    cmd->add_option("--temp-dir", a.temp_dir,
                    "Folder for the streaming converter's scratch files, about 160 bytes a triangle (default: the "
                    "output's folder)");
    add_paged_write_options(cmd, a.write);
    cmd->add_option("--threads", a.threads, "Threads (default: all cores)")->check(CLI::NonNegativeNumber);
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
    return cmd;
}

int run_convert(const ConvertArgs& a) {
    if (is_paged_scene_file(a.scene)) throw Error(a.scene + ": already a paged scene file (convert reads the formats render reads)");
    const PagedWriteOptions options = paged_write_options(a.write, a.threads);
    ConvertInputOptions input;
    input.memory_budget = parse_bytes(a.memory_budget, "--memory-budget");
    input.temp_dir = a.temp_dir;
    const Clock::time_point start = Clock::now();
    PagedWriteReport report;
    {
        ProgressBar bar("convert");
        ProgressCallback progress;
        if (!a.quiet) progress = [&bar](double f) { bar.update(f); };
        report = convert_file_to_paged(a.scene, a.output, options, input, progress);
    }
    print_write_report(a.output, report, ms_since(start));
    if (report.streamed)
        std::printf("%s: streamed within %s: %llu objects of at most %llu triangles, %s of scratch files, peak "
                    "resident %s\n",
                    a.output.c_str(), format_bytes(double(input.memory_budget)).c_str(),
                    (unsigned long long)report.objects, (unsigned long long)report.max_object_triangles,
                    format_bytes(double(report.scratch_bytes)).c_str(), format_bytes(peak_resident_bytes()).c_str());
    return 0;
}

CLI::App* add_generate_command(CLI::App& app, GenerateArgs& a) {
    std::string names;
    for (const std::string& n : generated_scene_names()) names += (names.empty() ? "" : ", ") + n;
    CLI::App* cmd = app.add_subcommand(
        "generate",
        "Write a procedural scene (unique geometry; forest: plus instances) as a paged file, or as .obj");
    cmd->add_option("name", a.name, "Scene kind: " + names)->required()->check(CLI::IsMember(generated_scene_names()));
    cmd->add_option("--triangles", a.triangles, "Triangles, e.g. 20M, 1.2G (K/M/G are powers of 1000 here; default 4M)");
    cmd->add_option("-o,--output", a.output, "Output: .rfpack (paged, written out of core) or .obj")->required();
    cmd->add_option("--seed", a.seed, "Seed: the same seed writes the same scene (default 1)");
    cmd->add_option("--statues", a.statues,
                    "Folder with stanford-bunny/ and stanford-dragon/ (e.g. ../shared/scenes); default: procedural "
                    "statues only");
    cmd->add_option("--max-object", a.max_object, "Largest object handed to the writer, in triangles (default 2M)");
    cmd->add_option("--instanced-triangles", a.instanced,
                    "forest: the triangles its instances show, e.g. 10G (default 25 times --triangles)");
    add_paged_write_options(cmd, a.write);
    cmd->add_option("--threads", a.threads, "Threads (default: all cores)")->check(CLI::NonNegativeNumber);
    cmd->add_flag("-q,--quiet", a.quiet, "No progress bar");
    return cmd;
}


int run_generate(const GenerateArgs& a) {
    GenerateOptions g;
    g.name = a.name;
    g.triangles = parse_count(a.triangles, "--triangles");
    g.seed = a.seed;
    g.statue_dir = a.statues;
    g.max_object_triangles = parse_count(a.max_object, "--max-object");
    if (!a.instanced.empty()) g.instanced_triangles = parse_count(a.instanced, "--instanced-triangles");
    const PagedWriteOptions options = paged_write_options(a.write, a.threads);
    const Clock::time_point start = Clock::now();
    PagedWriteReport report;
    {
        ProgressBar bar("generate");
        ProgressCallback progress;
        if (!a.quiet) progress = [&bar](double f) { bar.update(f); };
        report = generate_paged_scene(g, a.output, options, progress);
    }
    print_write_report(a.output, report, ms_since(start));
    return 0;
}

int run_paged_info(const std::string& path, bool verbose) {
    PagedSceneOptions small;
    // The pools are never touched, only the tables become resident; a budget
    // well inside the memory available, so that the open's check passes.
    small.memory_budget = std::min(size_t(1) << 30, memory_budget() / 4);
    const std::unique_ptr<PagedScene> scene = open_paged_scene(path, small);
    const PagedSceneInfo& i = scene->info();
    const Vec3f lo = i.bounds.lo, hi = i.bounds.hi;
    std::printf("%s: paged scene, %llu unique triangles in %llu quads, %u objects", path.c_str(),
                (unsigned long long)i.triangles, (unsigned long long)i.quads, i.objects);
    if (i.instances > 0)
        std::printf(", %llu instances placing %llu more triangles (%llu in all)", (unsigned long long)i.instances,
                    (unsigned long long)i.instanced_triangles, (unsigned long long)(i.instanced_triangles + i.triangles));
    std::printf("\n");
    std::printf("  file %s (%.1f bytes a unique triangle): %u geometry pages, %u attribute pages (at most %s each, %s), %u "
                "texture tiles; stored: %llu meshopt, %llu zstd, %llu raw; %s decoded\n",
                format_bytes(double(i.file_bytes)).c_str(), i.bytes_per_triangle(), i.geometry_pages,
                i.attribute_pages, format_bytes(double(i.attribute_page_bytes)).c_str(), to_string(i.attributes).c_str(),
                i.texture_pages, (unsigned long long)i.meshopt_pages, (unsigned long long)i.zstd_pages,
                (unsigned long long)i.raw_pages, format_bytes(double(i.decoded_bytes)).c_str());
    const std::string top = i.top_level == PagedTopLevel::Grid
                                ? "top grid " + std::to_string(i.grid[0]) + "x" + std::to_string(i.grid[1]) + "x" +
                                      std::to_string(i.grid[2])
                                : "top BVH of " + std::to_string(i.top_nodes) + " wide nodes";
    std::printf("  page reads: %s\n", i.page_reads.c_str());
    std::printf("  always resident %s: %s, %u materials, %u lights, %u textures\n",
                format_bytes(double(i.resident_bytes)).c_str(), top.c_str(), i.materials, i.lights, i.textures);
    std::printf("  bounds (%g, %g, %g) - (%g, %g, %g)\n", lo.x, lo.y, lo.z, hi.x, hi.y, hi.z);
    if (verbose) std::printf("  camera %s\n", to_string(scene->camera()).c_str());
    return 0;
}

}  // namespace rf::cli
