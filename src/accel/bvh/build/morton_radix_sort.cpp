// Parallel LSD radix sort (see morton_radix_sort.h).
//
// Each pass: per-block digit histograms (parallel over fixed blocks), one
// exclusive scan over (digit, block) so that every block knows where each of
// its digits goes, then a stable scatter (parallel over blocks). The blocks
// are fixed by the input size alone, so the output is the same for every
// thread count (it is a stable sort anyway).
#include "accel/bvh/build/morton_radix_sort.h"

#include <algorithm>
#include <cstddef>
#include <span>

#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

constexpr size_t kBlockSize = 32 * 1024;  // keys per histogram/scatter block
constexpr int kMaxDigitBits = 11;

template <class Key>
void radix_sort_impl(std::vector<Key>& keys, std::vector<uint32_t>& values, int key_bits) {
    if (keys.size() != values.size()) throw Error("radix_sort_pairs: keys and values differ in size");
    const size_t n = keys.size();
    if (n < 2 || key_bits <= 0) return;
    key_bits = std::min<int>(key_bits, static_cast<int>(8 * sizeof(Key)));
    const int passes = (key_bits + kMaxDigitBits - 1) / kMaxDigitBits;
    const int digit_bits = (key_bits + passes - 1) / passes;
    const size_t radix = size_t{1} << digit_bits;
    const size_t blocks = (n + kBlockSize - 1) / kBlockSize;

    std::vector<Key> key_tmp;
    std::vector<uint32_t> value_tmp;
    budgeted_resize(key_tmp, n, "radix sort: keys");
    budgeted_resize(value_tmp, n, "radix sort: values");
    std::vector<uint32_t> counts(blocks * radix);  // [block][digit]; becomes scatter offsets

    Key* src_keys = keys.data();
    uint32_t* src_values = values.data();
    Key* dst_keys = key_tmp.data();
    uint32_t* dst_values = value_tmp.data();

    for (int pass = 0; pass < passes; ++pass) {
        const int shift = pass * digit_bits;
        const Key mask = static_cast<Key>(radix - 1);
        parallel::for_range(size_t{0}, blocks, size_t{1}, [&](size_t lo, size_t hi) {
            for (size_t b = lo; b < hi; ++b) {
                uint32_t* count = counts.data() + b * radix;
                std::fill(count, count + radix, 0u);
                const size_t end = std::min(n, (b + 1) * kBlockSize);
                for (size_t i = b * kBlockSize; i < end; ++i) ++count[(src_keys[i] >> shift) & mask];
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
            if (digit_total == n) single_digit = true;
            sum += digit_total;
        }
        if (single_digit) continue;  // every key has this digit: the pass would copy
        parallel::for_range(size_t{0}, blocks, size_t{1}, [&](size_t lo, size_t hi) {
            for (size_t b = lo; b < hi; ++b) {
                uint32_t* offset = counts.data() + b * radix;
                const size_t end = std::min(n, (b + 1) * kBlockSize);
                for (size_t i = b * kBlockSize; i < end; ++i) {
                    const Key k = src_keys[i];
                    const uint32_t at = offset[(k >> shift) & mask]++;
                    dst_keys[at] = k;
                    dst_values[at] = src_values[i];
                }
            }
        });
        std::swap(src_keys, dst_keys);
        std::swap(src_values, dst_values);
    }
    if (src_keys != keys.data()) {
        keys.swap(key_tmp);
        values.swap(value_tmp);
    }
}

}  // namespace

void radix_sort_pairs(std::vector<uint32_t>& keys, std::vector<uint32_t>& values, int key_bits) {
    radix_sort_impl(keys, values, key_bits);
}

void radix_sort_pairs(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits) {
    radix_sort_impl(keys, values, key_bits);
}

}  // namespace rf
