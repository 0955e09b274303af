// Command-line options of paged scenes (docs/paged-scenes.md): the page
// caches' budgets for reading one (render, info, bench, view) and the
// layout for writing one (convert, generate).
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

#include "rayforge/ooc/paged_scene.h"

namespace rf::cli {

// --memory-budget, --geometry-budget, --attribute-budget, --texture-budget
// and --batch, bound to `options` (sizes parsed by parse_bytes).
void add_paged_read_options(CLI::App* cmd, PagedSceneOptions& options);

struct PagedWriteArgs {
    PagedCodec codec = PagedCodec::Meshopt;
    bool zstd = false;     // --zstd: --codec zstd
    int zstd_level = 3;
    PagedAttributes attributes = PagedAttributes::Shared;
    bool compact = false;  // --compact-attributes: --attributes compact
    std::string attribute_page = "8K";
    uint32_t quads_per_page = 4096;
    PagedTopLevel top = PagedTopLevel::WideBvh;
    bool flatten_instances = false;
    int grid = 32;
};
void add_paged_write_options(CLI::App* cmd, PagedWriteArgs& args);
PagedWriteOptions paged_write_options(const PagedWriteArgs& args, int threads);

// "1.5G", "512M", "64K", "1000" (bytes; K/M/G/T are powers of 1024); rf::Error naming `what` when malformed.
uint64_t parse_bytes(const std::string& text, const std::string& what);
// "20M" -> 20,000,000, "1.2G", "500K" (decimal units, for counts); rf::Error naming `what` when malformed.
uint64_t parse_count(const std::string& text, const std::string& what);
// "1.2 GiB", "340 MiB", ...
std::string format_bytes(double bytes);

}  // namespace rf::cli
