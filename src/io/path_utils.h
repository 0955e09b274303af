// Small path helpers shared by the scene loaders (OBJ/MTL, PLY, glTF, JSON).
// Paths are plain std::string; files written on Windows or case-insensitive
// file systems are the reason for most of these.
#pragma once

#include <optional>
#include <string>

namespace rf::io {

// The extension with its dot, lower-cased: "Scene.OBJ" -> ".obj", "README" -> "".
std::string lowercase_extension(const std::string& path);

// Turns Windows separators into '/': "textures\\a.tga" -> "textures/a.tga".
std::string normalize_separators(std::string path);

// `relative` resolved against the directory of `base_file` (separators
// normalised); absolute paths are returned unchanged.
std::string resolve_relative(const std::string& base_file, const std::string& relative);

// `path` itself when it exists; otherwise the same path with each component
// matched case-insensitively against its directory ("00_SKAP.JPG" finds
// "00_skap.JPG"); nullopt when nothing matches.
std::optional<std::string> find_file_case_insensitive(const std::string& path);

}  // namespace rf::io
