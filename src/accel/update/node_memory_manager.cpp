// The node memory manager of Garanzha 2014 ch. 2 (sec. 2.5, "memory
// manager"): an implicit balanced octary tree of free counts over a linear
// array of node slots.
//
// Data layout: one array per level; level 0 holds a 0/1 free flag per slot,
// level k the free count of each block of 8^k slots (entry b covers entries
// 8b .. 8b+7 of level k-1), and the top level one entry. No pointers: the
// tree is implicit.
//
// Allocation near a hint finds the nearest free slot on each side: climb
// from the hint while the rest of the current block on that side is empty,
// then descend to the nearest non-empty child; O(8 log8 n) each. The closer
// of the two is taken (the lower on a tie) and the counts on its path are
// decremented; freeing increments them.
//
// Parallelism: none (the adapt update allocates from one thread).
// Determinism: the result depends only on the sequence of calls.
#include "accel/update/node_memory_manager.h"

#include <algorithm>
#include <string>

#include "rayforge/core/error.h"

namespace rf {

void NodeMemoryManager::reset(uint32_t capacity, uint32_t used) {
    if (used > capacity) throw Error("node memory manager: " + std::to_string(used) + " used of " +
                                     std::to_string(capacity) + " slots");
    capacity_ = capacity;
    levels_.clear();
    std::vector<uint32_t> flags(capacity, 0);
    for (uint32_t i = used; i < capacity; ++i) flags[i] = 1;
    levels_.push_back(std::move(flags));
    while (levels_.back().size() > 1 || levels_.size() == 1) {
        const std::vector<uint32_t>& below = levels_.back();
        std::vector<uint32_t> level((below.size() + kArity - 1) / kArity, 0);
        if (level.empty()) level.push_back(0);
        for (size_t i = 0; i < below.size(); ++i) level[i / kArity] += below[i];
        levels_.push_back(std::move(level));
    }
}

void NodeMemoryManager::add(uint32_t slot, int delta) {
    uint32_t index = slot;
    for (auto& level : levels_) {
        level[index] = static_cast<uint32_t>(static_cast<int64_t>(level[index]) + delta);
        index /= kArity;
    }
}

uint32_t NodeMemoryManager::leftmost(int level, uint32_t index) const {
    for (int k = level; k > 0; --k) {
        const std::vector<uint32_t>& below = levels_[size_t(k - 1)];
        uint32_t child = index * kArity;
        while (below[child] == 0) ++child;  // some child has a free slot: the count says so
        index = child;
    }
    return index;
}

uint32_t NodeMemoryManager::rightmost(int level, uint32_t index) const {
    for (int k = level; k > 0; --k) {
        const std::vector<uint32_t>& below = levels_[size_t(k - 1)];
        uint32_t child = std::min<uint32_t>(index * kArity + kArity - 1, uint32_t(below.size() - 1));
        while (below[child] == 0) --child;
        index = child;
    }
    return index;
}

uint32_t NodeMemoryManager::next_free(uint32_t from) const {
    if (from >= capacity_) return kNone;
    uint32_t index = from;
    if (levels_[0][index]) return index;
    for (size_t k = 0; k + 1 < levels_.size(); ++k) {
        const std::vector<uint32_t>& level = levels_[k];
        const uint32_t block_end = std::min<uint32_t>((index / kArity + 1) * kArity, uint32_t(level.size()));
        for (uint32_t i = index + 1; i < block_end; ++i) {
            if (level[i]) return leftmost(int(k), i);
        }
        index /= kArity;
    }
    return kNone;
}

uint32_t NodeMemoryManager::prev_free(uint32_t from) const {
    if (capacity_ == 0) return kNone;
    uint32_t index = std::min(from, capacity_ - 1);
    if (levels_[0][index]) return index;
    for (size_t k = 0; k + 1 < levels_.size(); ++k) {
        const std::vector<uint32_t>& level = levels_[k];
        const uint32_t block_begin = index / kArity * kArity;
        for (uint32_t i = index; i-- > block_begin;) {
            if (level[i]) return rightmost(int(k), i);
        }
        index /= kArity;
    }
    return kNone;
}

uint32_t NodeMemoryManager::allocate_near(uint32_t hint) {
    if (free_count() == 0) return kNone;
    const uint32_t h = std::min(hint, capacity_ - 1);
    const uint32_t before = prev_free(h);
    const uint32_t after = next_free(h);
    uint32_t slot = before;
    if (after != kNone && (before == kNone || after - h < h - before)) slot = after;
    add(slot, -1);
    return slot;
}

void NodeMemoryManager::free(uint32_t slot) {
    if (slot >= capacity_ || levels_[0][slot]) {
        throw Error("node memory manager: slot " + std::to_string(slot) + " freed twice or out of range");
    }
    add(slot, +1);
}

}  // namespace rf
