// The AFF loader's entry points (load_aff, load_aff_at_time) and the parser's
// outer loop: reading files, expanding includes, and dispatching each
// statement to the part that reads it. The format is described in
// aff_parser.h.
#include "io/aff/aff_parser.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>

#include "io/file_reader.h"
#include "io/path_utils.h"

namespace rf {

namespace io::aff {

namespace fs = std::filesystem;

void warn(const std::string& message) { std::cerr << "rayforge: warning: " << message << '\n'; }
void note(const std::string& message) { std::cerr << "rayforge: note: " << message << '\n'; }

AffParser::AffParser(std::string root, const LoadOptions& options)
    : root_(std::move(root)), options_(options), polygon_what_(root_ + ": AFF polygon array"),
      geometry_what_(root_ + ": AFF geometry and keyframes with all includes expanded") {}

Scene AffParser::load(std::optional<double> time) {
    nodes_.push_back(Node{});
    std::error_code ec;
    std::string canonical = fs::weakly_canonical(root_, ec).string();
    if (ec) canonical = root_;
    parse_file(root_, canonical, 0);
    if (time) return assemble(*time);
    return assemble_animated(anim_start_ ? *anim_start_ : 0.0);
}

// Each file is read once; includes that occur again parse the same text.
std::string_view AffParser::file_text(const std::string& path) {
    auto it = texts_.find(path);
    if (it == texts_.end()) it = texts_.emplace(path, io::read_file(path)).first;
    return it->second;
}

void AffParser::parse_file(const std::string& path, const std::string& canonical, int depth) {
    std::string_view text = file_text(path);
    parsed_bytes_ += text.size();
    if (++expansions_ > kMaxExpansions || parsed_bytes_ > kMaxParsedBytes)
        throw file_error(path, 0, "too many include expansions (" + std::to_string(expansions_) + " files, " +
                                      std::to_string(parsed_bytes_) + " bytes; exponential include nesting?)");
    include_stack_.push_back(canonical);
    FileState state{TokenReader(path, text), node_stack_.size()};
    FileState* outer = file_;
    file_ = &state;
    parse_statements(depth);
    if (node_stack_.size() > state.block_base)
        throw file_error(path, nodes_[size_t(node_stack_.back())].line, "transform block '{' is not closed");
    file_ = outer;
    include_stack_.pop_back();
}

void AffParser::parse_statements(int depth) {
    Token t;
    while (in().next(t)) {
        const std::string_view k = t.text;
        const long line = t.line;
        if (k == "v") parse_view(line);
        else if (k == "b") background_ = in().read_vec3("background color");
        else if (k == "l") parse_light();
        else if (k == "am") ambient_light_ = max(in().read_vec3("ambient light"), Vec3f(0.0f));
        else if (k == "a") parse_anim_params(line);
        else if (k == "d") detail_level_ = in().read_int("detail level");
        else if (k == "f") parse_nff_material();
        else if (k == "fm") parse_fm_material();
        else if (k == "p") parse_polygon(false);
        else if (k == "pp") parse_polygon(true);
        else if (k == "tt") parse_textured_triangle(false);
        else if (k == "ttp") parse_textured_triangle(true);
        else if (k == "tpa") parse_animated_triangle(line);
        else if (k == "m") parse_mesh(line);
        else if (k == "s") parse_sphere(line);
        else if (k == "c") parse_cone(line);
        else if (k == "i") parse_include(depth, line);
        else if (k == "xs") parse_static_transform(line);
        else if (k == "x") parse_animated_transform(line);
        else if (k == "k") parse_keyframes(line);
        else if (k == "}") {
            if (node_stack_.size() <= file_->block_base) throw error(line, "'}' without an open transform block");
            node_stack_.pop_back();
        } else {
            throw error(line, "unknown keyword '" + std::string(k.substr(0, 32)) + "'");
        }
    }
}

// i detail_level file_name
void AffParser::parse_include(int depth, long line) {
    const int64_t detail = in().read_int("include detail level");
    const std::string name = in().read_word("include file name");
    if (detail > detail_level_) return;  // above the scene's detail level
    if (depth + 1 > kMaxIncludeDepth)
        throw error(line, "includes nested deeper than " + std::to_string(kMaxIncludeDepth) + " levels");
    // Resolved once per (including file, name): robots include the same parts hundreds of times.
    const std::string cache_key = in().path() + '\n' + name;
    auto cached = include_lookup_.find(cache_key);
    if (cached == include_lookup_.end()) {
        const std::string resolved = io::resolve_relative(in().path(), name);
        std::optional<std::string> found = io::find_file_case_insensitive(resolved);
        std::error_code ec;
        if (!found || !fs::is_regular_file(*found, ec)) throw error(line, "included file '" + name + "' not found");
        std::string canonical = fs::weakly_canonical(*found, ec).string();
        if (ec) canonical = *found;
        cached = include_lookup_.emplace(cache_key, std::make_pair(*found, canonical)).first;
    }
    const auto& [found, canonical] = cached->second;
    if (std::find(include_stack_.begin(), include_stack_.end(), canonical) != include_stack_.end())
        throw error(line, "include cycle: '" + name + "' includes itself");
    // Errors inside the included file name that file and line.
    parse_file(found, canonical, depth + 1);
}

}  // namespace io::aff

Scene load_aff_at_time(const std::string& path, double time, const LoadOptions& options) {
    if (!std::isfinite(time)) throw file_error(path, 0, "animation time is not finite");
    return io::aff::AffParser(path, options).load(time);
}

Scene load_aff(const std::string& path, const LoadOptions& options) {
    return io::aff::AffParser(path, options).load(std::nullopt);
}

}  // namespace rf
