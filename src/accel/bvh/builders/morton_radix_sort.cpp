// Parallel LSD radix sort (see morton_radix_sort.h).
//
// Each pass: per-block digit histograms (parallel over fixed blocks), one
// exclusive scan over (digit, block) so that every block knows where each of
// its digits goes, then a stable scatter (parallel over blocks). It is a
// stable sort, so the output is the same for every thread count and block
// size. Scratch arrays start uninitialised; 32-bit keys with 32-bit values
// are sorted packed into one 64-bit word (one stream to move per pass).
#include "accel/bvh/builders/morton_radix_sort.h"

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <memory>

#include "accel/bvh/builders/morton_buffer.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

constexpr size_t kBlockSize = 16 * 1024;  // keys per histogram/scatter block
constexpr int kMaxDigitBits = 11;

// Sorts by bits [low_bit, low_bit + key_bits) of the keys; values move along
// when kValues. Returns true when the result is in the tmp arrays.
template <class Key, bool kValues>
bool sort_impl(Key* keys, uint32_t* values, Key* key_tmp, uint32_t* value_tmp, size_t n, int low_bit,
               int key_bits) {
    if (n < 2 || key_bits <= 0) return false;
    key_bits = std::min<int>(key_bits, static_cast<int>(8 * sizeof(Key)) - low_bit);
    const int passes = (key_bits + kMaxDigitBits - 1) / kMaxDigitBits;
    const int digit_bits = (key_bits + passes - 1) / passes;
    const size_t radix = size_t{1} << digit_bits;
    const size_t blocks = (n + kBlockSize - 1) / kBlockSize;
    const Key mask = static_cast<Key>(radix - 1);

    std::unique_ptr<uint32_t[]> counts(new uint32_t[blocks * radix]);  // [block][digit]; becomes scatter offsets
    Key* src_keys = keys;
    uint32_t* src_values = values;
    Key* dst_keys = key_tmp;
    uint32_t* dst_values = value_tmp;

    for (int pass = 0; pass < passes; ++pass) {
        const int shift = low_bit + pass * digit_bits;
        parallel::for_range(size_t{0}, blocks, size_t{1}, [&](size_t lo, size_t hi) {
            for (size_t b = lo; b < hi; ++b) {
                uint32_t* count = counts.get() + b * radix;
                std::memset(count, 0, radix * sizeof(uint32_t));
                const Key* k = src_keys + b * kBlockSize;
                const size_t m = std::min(n, (b + 1) * kBlockSize) - b * kBlockSize;
                for (size_t i = 0; i < m; ++i) ++count[(k[i] >> shift) & mask];
            }
        });
        // Exclusive scan in digit-major, block-minor order: stable placement.
        uint32_t sum = 0;
        bool single_digit = false;
        for (size_t d = 0; d < radix; ++d) {
            uint32_t digit_total = 0;
            for (size_t b = 0; b < blocks; ++b) {
                uint32_t& c = counts[b * radix + d];
                const uint32_t here = c;
                c = sum + digit_total;
                digit_total += here;
            }
            if (digit_total == n) {
                single_digit = true;
                break;
            }
            sum += digit_total;
        }
        if (single_digit) continue;  // every key has this digit: the pass would copy
        parallel::for_range(size_t{0}, blocks, size_t{1}, [&](size_t lo, size_t hi) {
            for (size_t b = lo; b < hi; ++b) {
                uint32_t* offset = counts.get() + b * radix;
                const size_t begin = b * kBlockSize, end = std::min(n, (b + 1) * kBlockSize);
                const Key* __restrict sk = src_keys;
                Key* __restrict dk = dst_keys;
                for (size_t i = begin; i < end; ++i) {
                    const Key k = sk[i];
                    const uint32_t at = offset[(k >> shift) & mask]++;
                    dk[at] = k;
                    if constexpr (kValues) dst_values[at] = src_values[i];
                }
            }
        });
        std::swap(src_keys, dst_keys);
        std::swap(src_values, dst_values);
    }
    return src_keys != keys;
}

}  // namespace

namespace morton {

uint64_t* radix_sort_packed(uint64_t* items, uint64_t* tmp, size_t n, int low_bit, int key_bits) {
    return sort_impl<uint64_t, false>(items, nullptr, tmp, nullptr, n, low_bit, key_bits) ? tmp : items;
}

bool radix_sort_pairs(uint64_t* keys, uint32_t* values, uint64_t* key_tmp, uint32_t* value_tmp, size_t n,
                      int key_bits) {
    return sort_impl<uint64_t, true>(keys, values, key_tmp, value_tmp, n, 0, key_bits);
}

}  // namespace morton

void radix_sort_pairs(std::vector<uint32_t>& keys, std::vector<uint32_t>& values, int key_bits) {
    if (keys.size() != values.size()) throw Error("radix_sort_pairs: keys and values differ in size");
    const size_t n = keys.size();
    if (n < 2 || key_bits <= 0) return;
    // Packed as key << 32 | value: sorting by the key bits moves the value along.
    morton::Buffer<uint64_t> items(n, "radix sort: items"), tmp(n, "radix sort: items");
    parallel::for_range(size_t{0}, n, size_t{64 * 1024}, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) items[i] = (uint64_t{keys[i]} << 32) | values[i];
    });
    const uint64_t* sorted = morton::radix_sort_packed(items.data(), tmp.data(), n, 32, std::min(key_bits, 32));
    parallel::for_range(size_t{0}, n, size_t{64 * 1024}, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            keys[i] = static_cast<uint32_t>(sorted[i] >> 32);
            values[i] = static_cast<uint32_t>(sorted[i]);
        }
    });
}

void radix_sort_pairs(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits) {
    if (keys.size() != values.size()) throw Error("radix_sort_pairs: keys and values differ in size");
    const size_t n = keys.size();
    if (n < 2 || key_bits <= 0) return;
    morton::Buffer<uint64_t> key_tmp(n, "radix sort: keys");
    morton::Buffer<uint32_t> value_tmp(n, "radix sort: values");
    if (morton::radix_sort_pairs(keys.data(), values.data(), key_tmp.data(), value_tmp.data(), n, key_bits)) {
        std::memcpy(keys.data(), key_tmp.data(), n * sizeof(uint64_t));
        std::memcpy(values.data(), value_tmp.data(), n * sizeof(uint32_t));
    }
}

}  // namespace rf
