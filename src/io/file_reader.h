// Reading a whole file into memory, with a one-line rf::Error when it cannot be.
#pragma once

#include <string>

namespace rf::io {

// The file's bytes. Throws rf::Error "path: reason" when the file is missing,
// is not a regular file, or cannot be read completely.
std::string read_file(const std::string& path);

}  // namespace rf::io
