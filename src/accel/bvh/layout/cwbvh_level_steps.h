// The CWBVH emission's wide levels found without the host (issue 33 item 3;
// layout_convert.cu, replayed by tests/layout_convert_device_logic_test.cpp):
// pass 1 of cwbvh_emit_steps.h (discover, then enqueue the inner children in
// slot order) with each level's start and size kept in a record on the
// device, so no level waits for a host read of its size.
//
// The observation that makes it work: list the wide nodes in level order
// (the root first) and let P[i] be the exclusive prefix sum of their inner
// child counts. Every wide node but the root is the inner child of one
// before it, in that same order, so wide node i's first inner child is wide
// node 1 + P[i], and the level after [start, end) ends at 1 + P[end]. One
// exclusive scan of inner_count over a prefix of the array that covers the
// level (zeros past the discovered nodes) therefore gives every position:
// its length needs only an upper bound the host knows (at most 8^l nodes on
// level l, and at most `cap` in all), not the level's size.
#pragma once

#include <cstdint>

#include "accel/bvh/layout/cwbvh_emit_steps.h"
#include "rayforge/core/host_device.h"

namespace rf::cwbvh {

// Wide nodes [start, start + count) form a level; count 0: no such level.
struct LevelRecord {
    uint32_t start;
    uint32_t count;
};

// An error bit beside kErrorQuantize: a level ran past `cap` (device error).
inline constexpr uint32_t kErrorLevelOverflow = 2u;

// At most 8^level wide nodes on level `level`, and at most `cap`.
RF_HDI uint32_t level_width_bound(uint32_t level, uint32_t cap) {
    uint64_t width = 1;
    for (uint32_t l = 0; l < level && width < cap; ++l) width *= uint64_t(kWidth);
    return width < cap ? uint32_t(width) : cap;
}

// At most this many wide nodes on levels 0 .. `level` together: the length
// of the scan that covers level `level`.
RF_HDI uint32_t nodes_through_level_bound(uint32_t level, uint32_t cap) {
    uint64_t total = 0, width = 1;
    for (uint32_t l = 0; l <= level && total < cap; ++l, width *= uint64_t(kWidth)) total += width;
    return total < cap ? uint32_t(total) : cap;
}

// Thread k of level `level`'s discovery (pass 1a); nothing past the level.
RF_HDI void discover_in_level(const EmitView& v, const LevelRecord* records, uint32_t level, uint32_t k) {
    const LevelRecord r = records[level];
    if (k < r.count) discover(v, r.start + k);
}

// One thread, after the scan of inner_count into `prefix`: the record of
// level + 1 from level `level`'s. `cap`: the wide nodes the arrays hold; a
// level past it sets kErrorLevelOverflow and ends the loop.
RF_HDI void next_level_record(const uint32_t* prefix, const uint32_t* inner_count, LevelRecord* records,
                              uint32_t level, uint32_t cap, uint32_t* error) {
    const LevelRecord r = records[level];
    const uint32_t end = r.start + r.count;
    uint32_t next = 0;
    if (r.count != 0) {
        const uint64_t through = uint64_t(prefix[end - 1]) + inner_count[end - 1] + 1u;  // nodes through level + 1
        if (through > cap || through < end) {
            *error |= kErrorLevelOverflow;
        } else {
            next = uint32_t(through - end);
        }
    }
    records[level + 1] = {end, next};
}

// Thread k of level `level`'s enqueue (pass 1b) from the level-order prefix.
RF_HDI void enqueue_in_level(const EmitView& v, const LevelRecord* records, uint32_t level, const uint32_t* prefix,
                             uint32_t k) {
    const LevelRecord r = records[level];
    if (k >= r.count) return;
    const uint32_t i = r.start + k;
    v.first_child[i] = prefix[i];
    enqueue_children(v, i, 1u);  // first inner child: 1 + P[i]
}

}  // namespace rf::cwbvh
