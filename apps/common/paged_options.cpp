#include "paged_options.h"

#include <cctype>
#include <cmath>
#include <cstdio>

#include "option_binding.h"
#include "rayforge/core/error.h"

namespace rf::cli {

namespace {

// "1.5G" -> 1.5 and "G"; false when the text does not start with a number.
bool split_number(const std::string& text, double& value, std::string& unit) {
    size_t used = 0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {
        return false;
    }
    unit = text.substr(used);
    return used > 0;
}

}  // namespace

uint64_t parse_bytes(const std::string& text, const std::string& what) {
    double value = 0.0;
    std::string unit;
    const bool number = split_number(text, value, unit);
    if (!unit.empty() && (unit.back() == 'B' || unit.back() == 'b')) unit.pop_back();
    if (!unit.empty() && unit.back() == 'i') unit.pop_back();
    double scale = 1.0;
    if (unit.size() == 1) {
        const char u = char(std::toupper(unsigned(unit[0])));
        scale = u == 'K' ? 1024.0 : u == 'M' ? 1048576.0 : u == 'G' ? 1073741824.0 : u == 'T' ? 1099511627776.0 : 0.0;
    } else if (!unit.empty()) {
        scale = 0.0;
    }
    const double bytes = value * scale;
    if (!number || scale == 0.0 || !std::isfinite(bytes) || bytes < 0.0 || bytes > 1e18)
        throw Error(what + ": '" + text + "' is not a size (e.g. 512M, 2G, 65536)");
    return uint64_t(std::llround(bytes));
}

uint64_t parse_count(const std::string& text, const std::string& what) {
    double value = 0.0;
    std::string unit;
    const bool number = split_number(text, value, unit);
    const double scale = unit.empty() ? 1.0 : unit == "K" || unit == "k" ? 1e3 : unit == "M" ? 1e6 : unit == "G" ? 1e9 : 0.0;
    if (!number || scale == 0.0 || !(value >= 0.0) || value * scale > 1e13)
        throw Error(what + ": '" + text + "' is not a count (e.g. 500K, 20M, 1.2G)");
    return uint64_t(value * scale + 0.5);
}

std::string format_bytes(double bytes) {
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    int u = 0;
    while (bytes >= 1024.0 && u < 4) {
        bytes /= 1024.0;
        ++u;
    }
    char text[32];
    std::snprintf(text, sizeof(text), u == 0 ? "%.0f %s" : "%.2f %s", bytes, units[u]);
    return text;
}

void add_paged_read_options(CLI::App* cmd, PagedSceneOptions& o) {
    const auto size_option = [cmd](const std::string& name, size_t& field, const std::string& help) {
        cmd->add_option_function<std::string>(
            name, [&field, name](const std::string& text) { field = parse_bytes(text, name); }, help);
    };
    size_option("--memory-budget", o.memory_budget,
                "Paged scenes: memory for the page caches together, e.g. 512M, 2G (default 1G); split "
                "geometry 70%, attributes 15%, textures 15% (80/20 without textures), a share's surplus over "
                "what its cache can use going to the others; more than the memory available is refused");
    size_option("--geometry-budget", o.geometry_budget,
                "Paged scenes: the geometry cache's budget (overrides its share)");
    size_option("--attribute-budget", o.attribute_budget,
                "Paged scenes: the surface-attribute cache's budget (overrides its share)");
    size_option("--texture-budget", o.texture_budget,
                "Paged scenes: the texture-tile cache's budget (overrides its share)");
    cmd->add_option("--batch", o.batch_paths,
                    "Paged scenes: paths traced as one batch (1024..16777216, default 262144; about 250 bytes a path)")
        ->check(CLI::Range(1024u, 16u << 20));
}

void add_paged_write_options(CLI::App* cmd, PagedWriteArgs& a) {
    CLI::Option* codec = add_named_option(
        cmd, "--codec", a.codec, parse_paged_codec, {"meshopt", "zstd", "none"},
        "How pages are stored: meshopt (meshoptimizer's vertex and index codecs, then zstd; the default), zstd "
        "(zstd alone) or none (raw); a page is kept raw where the codec does not make it smaller");
    cmd->add_flag("--zstd", a.zstd, "The same as --codec zstd")->excludes(codec);
    cmd->add_option("--zstd-level", a.zstd_level, "zstd level of --codec meshopt and zstd, 1..19 (default 3)")
        ->check(CLI::Range(1, 19));
    CLI::Option* attributes = add_named_option(
        cmd, "--attributes", a.attributes, parse_paged_attributes, {"shared", "full", "compact"},
        "How shading normals, uvs and materials are stored: shared (per-vertex data shared within a page; the "
        "default, exact but for an octahedral geometric normal), full (a 64-byte record a triangle, exact) or "
        "compact (a 32-byte record: half-float uvs, no normal-map tangents, no uv-density mip selection)");
    cmd->add_flag("--compact-attributes", a.compact, "The same as --attributes compact")->excludes(attributes);
    cmd->add_option("--attribute-page", a.attribute_page,
                    "Bytes per surface-attribute page (at most, before the codec), a power of two from 1K to 1M (default 8K)");
    cmd->add_option("--page-quads", a.quads_per_page, "Quads per geometry page, 64..4096 (default 4096, Garanzha 2014's 4K)")
        ->check(CLI::Range(64, 4096));
    add_named_option(cmd, "--top", a.top, parse_paged_top_level, {"bvh", "grid"},
                     "How rays find pages: bvh (one wide BVH over the page bounds, the default) or grid (Garanzha "
                     "2014's top grid with a BVH in every cell)");
    cmd->add_flag("--flatten-instances", a.flatten_instances,
                  "Write every instance's triangles in world space instead of a mesh placed by several instances "
                  "once plus its instances");
    cmd->add_option("--grid", a.grid, "--top grid: cells on the scene's longest axis, 1..256 (default 32)")
        ->check(CLI::Range(1, 256));
}

PagedWriteOptions paged_write_options(const PagedWriteArgs& a, int threads) {
    PagedWriteOptions o;
    o.codec = a.zstd ? PagedCodec::Zstd : a.codec;
    o.zstd_level = a.zstd_level;
    o.attributes = a.compact ? PagedAttributes::Compact : a.attributes;
    o.attribute_page_bytes = uint32_t(parse_bytes(a.attribute_page, "--attribute-page"));
    o.quads_per_page = a.quads_per_page;
    o.top_level = a.top;
    o.flatten_instances = a.flatten_instances;
    o.grid_resolution = a.grid;
    o.threads = threads;
    return o;
}

}  // namespace rf::cli
