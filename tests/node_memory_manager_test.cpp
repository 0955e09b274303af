// The adapt update's node memory manager (Garanzha 2014 ch. 2, sec. 2.5):
// allocation takes the free slot nearest the hint, and under random
// allocate/free sequences no slot is ever lost or handed out twice.
#include "accel/update/node_memory_manager.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <set>

#include "rayforge/core/error.h"

namespace rf {
namespace {

// The reference answer: the free slot nearest `hint`, the lower on a tie.
uint32_t nearest(const std::set<uint32_t>& free_slots, uint32_t hint) {
    auto after = free_slots.lower_bound(hint);
    if (after == free_slots.end()) return *std::prev(after);
    if (*after == hint || after == free_slots.begin()) return *after;
    const uint32_t before = *std::prev(after);
    return *after - hint < hint - before ? *after : before;
}

TEST(NodeMemoryManager, ResetMarksPrefixUsed) {
    NodeMemoryManager memory(100, 37);
    EXPECT_EQ(memory.capacity(), 100u);
    EXPECT_EQ(memory.free_count(), 63u);
    EXPECT_FALSE(memory.is_free(36));
    EXPECT_TRUE(memory.is_free(37));
    EXPECT_EQ(memory.allocate_near(0), 37u);
    EXPECT_EQ(memory.allocate_near(1000), 99u);
}

TEST(NodeMemoryManager, AllocatesNearestAndNeverTwice) {
    for (uint32_t capacity : {1u, 7u, 8u, 9u, 64u, 65u, 513u, 5000u}) {
        std::mt19937 rng(capacity);
        NodeMemoryManager memory(capacity);
        std::set<uint32_t> free_slots;
        for (uint32_t i = 0; i < capacity; ++i) free_slots.insert(i);
        std::set<uint32_t> used;
        for (int step = 0; step < 20000; ++step) {
            const bool allocate = used.empty() || (!free_slots.empty() && rng() % 100 < 55);
            if (allocate) {
                const uint32_t hint = rng() % (capacity + 3);
                const uint32_t expected = nearest(free_slots, std::min(hint, capacity - 1));
                const uint32_t got = memory.allocate_near(hint);
                ASSERT_EQ(got, expected) << "capacity " << capacity << " hint " << hint;
                ASSERT_TRUE(used.insert(got).second) << "slot " << got << " handed out twice";
                free_slots.erase(got);
            } else {
                auto it = used.begin();
                std::advance(it, rng() % used.size());
                memory.free(*it);
                free_slots.insert(*it);
                used.erase(it);
            }
            ASSERT_EQ(memory.free_count(), free_slots.size());
        }
        for (uint32_t i = 0; i < capacity; ++i) EXPECT_EQ(memory.is_free(i), free_slots.count(i) == 1);
    }
}

TEST(NodeMemoryManager, FullAndDoubleFree) {
    NodeMemoryManager memory(20);
    for (uint32_t i = 0; i < 20; ++i) EXPECT_EQ(memory.allocate_near(0), i);
    EXPECT_EQ(memory.allocate_near(5), NodeMemoryManager::kNone);
    memory.free(7);
    EXPECT_THROW(memory.free(7), Error);
    EXPECT_THROW(memory.free(20), Error);
    EXPECT_EQ(memory.allocate_near(19), 7u);
    EXPECT_EQ(memory.free_count(), 0u);
}

}  // namespace
}  // namespace rf
