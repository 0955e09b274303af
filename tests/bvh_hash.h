// A fingerprint of a BVH for the tests that pin a builder's output: FNV-1a
// over the nodes (boxes bit for bit, links, counts) and the primitive order.
#pragma once

#include <cstddef>
#include <cstdint>

#include "rayforge/accel/bvh/bvh.h"

namespace rf::test {

inline uint64_t bvh_hash(const Bvh& bvh) {
    uint64_t h = 1469598103934665603ull;
    auto eat = [&](const void* p, size_t bytes) {
        const auto* b = static_cast<const unsigned char*>(p);
        for (size_t i = 0; i < bytes; ++i) h = (h ^ b[i]) * 1099511628211ull;
    };
    for (const BvhNode& n : bvh.nodes) {
        eat(&n.bounds, sizeof n.bounds);
        eat(&n.first, sizeof n.first);
        eat(&n.count, sizeof n.count);
    }
    eat(bvh.prim_indices.data(), bvh.prim_indices.size() * sizeof(uint32_t));
    return h;
}

}  // namespace rf::test
