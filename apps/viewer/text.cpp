#include "text.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include "rayforge/core/error.h"

namespace rf::viewer {

std::string read_text_file(const std::string& path, const std::string& what) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw Error(path + ": cannot open " + what);
    std::stringstream text;
    text << in.rdbuf();
    if (in.bad()) throw Error(path + ": cannot read " + what);
    return text.str();
}

double parse_number(const std::string& text, const std::string& what) {
    size_t used = 0;
    double value = 0.0;
    try {
        value = std::stod(text, &used);
    } catch (const std::exception&) {  // not a number, or out of double's range
        used = 0;
    }
    if (used == 0 || used != text.size() || !std::isfinite(value))
        throw Error("expected " + what + ", got '" + text + "'");
    return value;
}

std::string number_text(double value) {
    char text[32];
    std::snprintf(text, sizeof text, "%.9g", value);
    return text;
}

}  // namespace rf::viewer
