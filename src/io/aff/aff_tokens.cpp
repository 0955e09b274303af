// TokenReader: typed reads on AFF tokens (numbers through io/number_parsing.h),
// with the "file:line: reason" errors of the format.
#include "io/aff/aff_tokens.h"

#include <cmath>

#include "io/number_parsing.h"

namespace rf::io::aff {

Token TokenReader::expect_token(const char* what) {
    Token t;
    if (!tokens_.next(t)) throw error(tokens_.line(), std::string("unexpected end of file, expected ") + what);
    return t;
}

float TokenReader::read_float(const char* what) {
    Token t = expect_token(what);
    float value = 0.0f;
    const char* end = t.text.data() + t.text.size();
    const char* after = io::parse_float(t.text.data(), end, value);
    if (after != end) throw error(t.line, "bad number '" + std::string(t.text.substr(0, 24)) + "' in " + what);
    if (!std::isfinite(value)) throw error(t.line, std::string("non-finite number in ") + what);
    return value;
}

Vec3f TokenReader::read_vec3(const char* what) {
    float x = read_float(what);
    float y = read_float(what);
    float z = read_float(what);
    return {x, y, z};
}

int64_t TokenReader::read_int(const char* what, long* line) {
    Token t = expect_token(what);
    int64_t value = 0;
    const char* end = t.text.data() + t.text.size();
    const char* after = io::parse_int(t.text.data(), end, value);
    if (after != end) throw error(t.line, "bad integer '" + std::string(t.text.substr(0, 24)) + "' in " + what);
    if (line) *line = t.line;
    return value;
}

size_t TokenReader::read_count(const char* what, size_t numbers_each) {
    long line = 0;
    int64_t n = read_int(what, &line);
    if (n < 0) throw error(line, std::string("negative ") + what);
    if (uint64_t(n) > 0xFFFFFFFFull) throw error(line, std::string(what) + " " + std::to_string(n) + " exceed 32-bit indices");
    // Each number takes at least one character and one separator.
    const uint64_t min_bytes = uint64_t(n) * numbers_each * 2;
    if (min_bytes > tokens_.remaining() + 1)
        throw error(line, std::string(what) + " " + std::to_string(n) + " exceeds what is left of the file (" +
                              std::to_string(tokens_.remaining()) + " bytes)");
    return size_t(n);
}

uint32_t TokenReader::read_index(const char* what, size_t count) {
    long line = 0;
    int64_t i = read_int(what, &line);
    if (i < 0 || uint64_t(i) >= count)
        throw error(line, std::string(what) + " index " + std::to_string(i) + " out of range (" +
                              std::to_string(count) + " defined)");
    return uint32_t(i);
}

std::string TokenReader::read_word(const char* what) {
    Token t = expect_token(what);
    if (t.text == "{" || t.text == "}") throw error(t.line, std::string("expected ") + what + ", found '" + std::string(t.text) + "'");
    return std::string(t.text);
}

void TokenReader::expect_open_brace(const char* what) {
    Token t = expect_token("'{'");
    if (t.text != "{") throw error(t.line, std::string("expected '{' after ") + what + ", found '" + std::string(t.text.substr(0, 24)) + "'");
}

bool TokenReader::next_is_number() {
    Token t;
    if (!tokens_.peek(t)) return false;
    float v;
    const char* end = t.text.data() + t.text.size();
    return io::parse_float(t.text.data(), end, v) == end;
}

}  // namespace rf::io::aff
