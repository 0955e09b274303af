// Fast decimal number parsing for the text loaders (OBJ, ascii PLY).
//
// Scanned meshes hold millions of short numbers such as "0.0503644". These
// take Clinger's fast path: a mantissa below 2^24 and a power of ten up to
// 10^10 are both exact floats, so one float multiply or divide is correctly
// rounded and equals what std::from_chars returns. Anything else (long
// mantissas, large exponents, nan, inf) goes to std::from_chars.
#pragma once

#include <charconv>
#include <cstdint>
#include <system_error>

namespace rf::io {

inline bool is_digit(char c) { return static_cast<unsigned char>(c - '0') < 10; }

// Parses a float at the start of [p, end) (an optional '+' is accepted).
// Returns the end of the number, or nullptr when there is none.
inline const char* parse_float(const char* p, const char* end, float& out) {
    static constexpr float kPow10[] = {1e0f, 1e1f, 1e2f, 1e3f, 1e4f, 1e5f, 1e6f, 1e7f, 1e8f, 1e9f, 1e10f};
    const char* const start = (p < end && *p == '+') ? p + 1 : p;
    const char* q = start;
    bool negative = false;
    if (q < end && *q == '-') {
        negative = true;
        ++q;
    }
    uint64_t mantissa = 0;
    int significant = 0, exponent = 0;
    bool any_digit = false;
    auto take_digit = [&](char c) {
        any_digit = true;
        if (mantissa != 0 || c != '0') {
            ++significant;
            if (significant <= 18) mantissa = mantissa * 10 + uint64_t(c - '0');
        }
    };
    while (q < end && is_digit(*q)) take_digit(*q++);
    if (q < end && *q == '.') {
        ++q;
        while (q < end && is_digit(*q)) {
            take_digit(*q++);
            --exponent;
        }
    }
    if (q < end && (*q == 'e' || *q == 'E') && any_digit) {
        const char* e = q + 1;
        bool exp_negative = false;
        if (e < end && (*e == '-' || *e == '+')) exp_negative = *e++ == '-';
        int value = 0;
        bool exp_digit = false;
        while (e < end && is_digit(*e)) {
            exp_digit = true;
            if (value < 10000) value = value * 10 + (*e - '0');
            ++e;
        }
        if (exp_digit) {
            exponent += exp_negative ? -value : value;
            q = e;
        }
    }
    if (any_digit && significant <= 18 && mantissa <= (1u << 24) && exponent >= -10 && exponent <= 10) {
        float value = float(mantissa);
        value = exponent < 0 ? value / kPow10[-exponent] : value * kPow10[exponent];
        out = negative ? -value : value;
        return q;
    }
    auto [ptr, ec] = std::from_chars(start, end, out);
    if (ec != std::errc()) return nullptr;
    return ptr;
}

// Parses a decimal integer (optional sign) of at most 18 digits at the start
// of [p, end). Returns the end of the number, or nullptr when there is none.
inline const char* parse_int(const char* p, const char* end, int64_t& out) {
    bool negative = false;
    if (p < end && (*p == '-' || *p == '+')) negative = *p++ == '-';
    const char* digits = p;
    int64_t value = 0;
    while (p < end && is_digit(*p)) {
        if (p - digits >= 18) return nullptr;  // out of any range we accept
        value = value * 10 + (*p++ - '0');
    }
    if (p == digits) return nullptr;
    out = negative ? -value : value;
    return p;
}

}  // namespace rf::io
