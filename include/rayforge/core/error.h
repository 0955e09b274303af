// rf::Error: the one exception type thrown at the library's boundary (files,
// options, budgets). what() is a single line: "context: reason".
#pragma once

#include <stdexcept>
#include <string>

namespace rf {

class Error : public std::runtime_error {
public:
    explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// "file:line: reason" or "file: reason" (line <= 0), for loaders.
[[nodiscard]] Error file_error(const std::string& path, long line, const std::string& reason);
// "file: byte OFFSET: reason", for binary formats.
[[nodiscard]] Error file_byte_error(const std::string& path, unsigned long long offset,
                                    const std::string& reason);

}  // namespace rf
