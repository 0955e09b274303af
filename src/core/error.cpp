#include "rayforge/core/error.h"

#include <algorithm>

namespace rf {

namespace {
// Messages stay on one line whatever a third-party library put in them.
std::string one_line(std::string s) {
    std::replace(s.begin(), s.end(), '\n', ' ');
    std::replace(s.begin(), s.end(), '\r', ' ');
    while (!s.empty() && s.back() == ' ') s.pop_back();
    return s;
}
}  // namespace

Error file_error(const std::string& path, long line, const std::string& reason) {
    if (line > 0) return Error(one_line(path + ":" + std::to_string(line) + ": " + reason));
    return Error(one_line(path + ": " + reason));
}

Error file_byte_error(const std::string& path, unsigned long long offset, const std::string& reason) {
    return Error(one_line(path + ": byte " + std::to_string(offset) + ": " + reason));
}

}  // namespace rf
