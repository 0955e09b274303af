// The node memory manager of Garanzha 2014 ch. 2 (sec. 2.5): a linear array
// of BVH node slots with, over it, an implicit balanced octary tree MEM whose
// entries hold only the count of free slots in their block. Allocation takes
// the free slot nearest to a hint (the parent's slot), so that parents and
// children stay close in memory through many detach/attach operations.
#pragma once

#include <cstdint>
#include <vector>

namespace rf {

class NodeMemoryManager {
public:
    static constexpr uint32_t kNone = 0xffffffffu;
    static constexpr uint32_t kArity = 8;

    NodeMemoryManager() = default;
    // `capacity` slots, the first `used` of them allocated, the rest free.
    explicit NodeMemoryManager(uint32_t capacity, uint32_t used = 0) { reset(capacity, used); }
    void reset(uint32_t capacity, uint32_t used = 0);

    // The free slot nearest to `hint` (the lower one on a tie), now
    // allocated; kNone when every slot is taken.
    uint32_t allocate_near(uint32_t hint);
    // Returns an allocated slot; throws rf::Error for a free or unknown slot.
    void free(uint32_t slot);

    [[nodiscard]] bool is_free(uint32_t slot) const { return slot < capacity_ && levels_[0][slot] != 0; }
    [[nodiscard]] uint32_t capacity() const { return capacity_; }
    [[nodiscard]] uint32_t free_count() const { return levels_.empty() ? 0 : levels_.back()[0]; }
    [[nodiscard]] uint32_t used_count() const { return capacity_ - free_count(); }

private:
    // First free slot >= from, or kNone; last free slot <= from, or kNone.
    [[nodiscard]] uint32_t next_free(uint32_t from) const;
    [[nodiscard]] uint32_t prev_free(uint32_t from) const;
    [[nodiscard]] uint32_t leftmost(int level, uint32_t index) const;
    [[nodiscard]] uint32_t rightmost(int level, uint32_t index) const;
    void add(uint32_t slot, int delta);

    uint32_t capacity_ = 0;
    // levels_[0][i]: 1 when slot i is free; levels_[k][b]: free slots in
    // block b of 8^k slots; the last level has one entry (all free slots).
    std::vector<std::vector<uint32_t>> levels_;
};

}  // namespace rf
