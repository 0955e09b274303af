// Parallel LSD radix sort of (key, value) pairs for the Morton-ordered BVH
// builders (the CPU counterpart of the GPU radix sort of Merrill and
// Grimshaw 2010 that Karras 2012 and Garanzha's HLBVH2 rely on).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace rf {

// Sorts keys ascending by their low `key_bits` bits (higher bits must be 0),
// moving values[i] along with keys[i]. Stable, so equal keys keep the order
// of their values' input positions; the result does not depend on the thread
// count. Passes of at most 11 bits each (30 bits: 3 passes of 10 bits; 63
// bits: 6 passes of 10-11 bits); a pass whose digit is the same for every key
// is skipped. keys.size() == values.size().
void radix_sort_pairs(std::vector<uint32_t>& keys, std::vector<uint32_t>& values, int key_bits);
void radix_sort_pairs(std::vector<uint64_t>& keys, std::vector<uint32_t>& values, int key_bits);

namespace morton {

// The same sort on raw arrays of n elements, with scratch arrays of n
// elements each (their contents are overwritten):
//
// Packed items (a 30-bit code above a 32-bit triangle index, say), sorted by
// bits [low_bit, low_bit + key_bits) of each item (bits above them must be
// 0). Returns `items` or `tmp`, whichever holds the sorted items.
uint64_t* radix_sort_packed(uint64_t* items, uint64_t* tmp, size_t n, int low_bit, int key_bits);

// Separate keys and values, as radix_sort_pairs. Returns true when the sorted
// pairs ended up in key_tmp and value_tmp, false when in keys and values.
bool radix_sort_pairs(uint64_t* keys, uint32_t* values, uint64_t* key_tmp, uint32_t* value_tmp, size_t n,
                      int key_bits);

}  // namespace morton
}  // namespace rf
