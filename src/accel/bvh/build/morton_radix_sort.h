// Parallel LSD radix sort of (key, value) pairs for the Morton-ordered BVH
// builders (the CPU counterpart of the GPU radix sort of Merrill and
// Grimshaw 2010 that Karras 2012 and Garanzha's HLBVH2 rely on).
#pragma once

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

}  // namespace rf
