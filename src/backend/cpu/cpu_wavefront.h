// What the CPU's wavefront path tracer (backend/cpu/cpu_renderer.cpp, over
// render/wavefront.h) exposes to tests: its chunk size and its queue sort.
#pragma once

#include <cstdint>
#include <span>

namespace rf {

// Paths in flight at once: bounds the queues' memory (about 200 bytes a path).
inline constexpr uint32_t kWavefrontChunkPaths = 1u << 16;

// Stable sort of `queue` by `keys` (keys[i] belongs to queue[i]; both are
// permuted together): a least-significant-digit radix sort, 8 bits a round.
void sort_queue_by_key(std::span<uint32_t> queue, std::span<uint32_t> keys);

}  // namespace rf
