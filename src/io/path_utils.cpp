#include "io/path_utils.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <system_error>

namespace fs = std::filesystem;

namespace rf::io {

namespace {

std::string to_lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

// The entry of `dir` whose name equals `name` ignoring case, if any.
std::optional<fs::path> match_in_directory(const fs::path& dir, const std::string& name) {
    std::error_code ec;
    const std::string wanted = to_lower(name);
    for (fs::directory_iterator it(dir.empty() ? fs::path(".") : dir, ec), end; !ec && it != end; it.increment(ec)) {
        if (to_lower(it->path().filename().string()) == wanted) return dir / it->path().filename();
    }
    return std::nullopt;
}

}  // namespace

std::string lowercase_extension(const std::string& path) {
    return to_lower(fs::path(path).extension().string());
}

std::string normalize_separators(std::string path) {
    std::replace(path.begin(), path.end(), '\\', '/');
    return path;
}

std::string resolve_relative(const std::string& base_file, const std::string& relative) {
    fs::path rel(normalize_separators(relative));
    if (rel.is_absolute()) return rel.string();
    return (fs::path(base_file).parent_path() / rel).lexically_normal().string();
}

std::optional<std::string> find_file_case_insensitive(const std::string& path) {
    std::error_code ec;
    if (fs::exists(path, ec)) return path;
    // Walk the components, fixing the case of each one that does not exist.
    fs::path resolved;
    for (const fs::path& part : fs::path(path)) {
        fs::path candidate = resolved / part;
        if (part == "/" || part == "." || part == ".." || fs::exists(candidate, ec)) {
            resolved = candidate;
            continue;
        }
        std::optional<fs::path> match = match_in_directory(resolved, part.string());
        if (!match) return std::nullopt;
        resolved = *match;
    }
    return resolved.string();
}

}  // namespace rf::io
