// Text the viewer reads: whole files (scripts, bookmarks) and numbers typed
// into a script or a setting, each failing with one rf::Error line.
#pragma once

#include <string>

namespace rf::viewer {

// The file's bytes; `what` names it in errors ("the script").
std::string read_text_file(const std::string& path, const std::string& what);

// A finite number spelled out completely ("1.5", "-2e3"; not "1.5x", "nan",
// "1e999"); `what` says what was expected ("a count").
double parse_number(const std::string& text, const std::string& what = "a number");

// The shortest form (%.9g) that reads back as the same float.
std::string number_text(double value);

}  // namespace rf::viewer
