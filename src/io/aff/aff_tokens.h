// AFF tokens and the typed reads on them: words, numbers, counts and indices,
// each failure an rf::Error "file:line: reason" naming what was expected.
//
// Tokens are whitespace-separated words; '{' and '}' are words of their own;
// '#' and '%' start a comment that runs to the end of the line.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>

#include "rayforge/core/error.h"
#include "rayforge/math/vec.h"

namespace rf::io::aff {

struct Token {
    std::string_view text;
    long line = 0;
};

// Splits a file's text into tokens, one token of lookahead. Inline: every
// number of a scene goes through here.
class Tokenizer {
public:
    explicit Tokenizer(std::string_view text) : text_(text) {}

    bool next(Token& out) {
        if (!peek(out)) return false;
        pos_ = peek_end_;
        line_ = peek_line_after_;
        has_peek_ = false;
        return true;
    }
    bool peek(Token& out) {
        if (!has_peek_) compute_peek();
        if (peek_token_.text.empty()) return false;
        out = peek_token_;
        return true;
    }
    [[nodiscard]] long line() const { return line_; }
    [[nodiscard]] size_t remaining() const { return text_.size() - pos_; }

private:
    static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }
    void compute_peek() {
        size_t p = pos_;
        long line = line_;
        for (;;) {
            while (p < text_.size() && is_space(text_[p])) {
                if (text_[p] == '\n') ++line;
                ++p;
            }
            if (p < text_.size() && (text_[p] == '#' || text_[p] == '%')) {
                while (p < text_.size() && text_[p] != '\n') ++p;
                continue;
            }
            break;
        }
        size_t start = p;
        if (p < text_.size() && (text_[p] == '{' || text_[p] == '}')) {
            ++p;
        } else {
            while (p < text_.size() && !is_space(text_[p]) && text_[p] != '{' && text_[p] != '}' && text_[p] != '#' &&
                   text_[p] != '%')
                ++p;
        }
        peek_token_ = Token{text_.substr(start, p - start), line};
        peek_end_ = p;
        peek_line_after_ = line;
        has_peek_ = true;
    }

    std::string_view text_;
    size_t pos_ = 0;
    long line_ = 1;
    bool has_peek_ = false;
    Token peek_token_;
    size_t peek_end_ = 0;
    long peek_line_after_ = 1;
};

// The tokens of one file with typed reads; `what` names the expected item in
// error messages ("unexpected end of file, expected mesh vertex").
class TokenReader {
public:
    TokenReader(std::string path, std::string_view text) : path_(std::move(path)), tokens_(text) {}

    [[nodiscard]] const std::string& path() const { return path_; }
    [[nodiscard]] Error error(long line, const std::string& reason) const { return file_error(path_, line, reason); }

    bool next(Token& out) { return tokens_.next(out); }
    bool peek(Token& out) { return tokens_.peek(out); }

    Token expect_token(const char* what);
    float read_float(const char* what);  // finite
    Vec3f read_vec3(const char* what);
    int64_t read_int(const char* what, long* line = nullptr);
    // A count of items of `numbers_each` numbers each, checked against what is left of the file.
    size_t read_count(const char* what, size_t numbers_each);
    uint32_t read_index(const char* what, size_t count);  // in [0, count)
    std::string read_word(const char* what);              // not a brace
    void expect_open_brace(const char* what);
    bool next_is_number();

private:
    std::string path_;
    Tokenizer tokens_;
};

}  // namespace rf::io::aff
