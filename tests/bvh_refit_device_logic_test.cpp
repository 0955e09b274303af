// The per-thread logic of the CUDA refit (backend/cuda/bvh_refit.cu) run on
// the CPU the way its kernels run it: the parents kernel's threads in a
// shuffled order, then the refit kernel's leaf threads in shuffled orders,
// one at a time and on many std::threads, so the "second arrival goes on"
// counters are exercised. The boxes must equal the serial refit bit for bit,
// every inner node must see exactly two arrivals, and the counters must be
// zero again after each pass; counters that let the first arrival go on
// are caught.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <numeric>
#include <random>
#include <thread>
#include <vector>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/refit.h"
#include "accel/bvh/refit_steps.h"
#include "accel_test_scenes.h"

namespace rf {
namespace {

std::vector<uint32_t> shuffled(std::vector<uint32_t> ids, uint32_t seed) {
    std::mt19937 rng(seed);
    std::shuffle(ids.begin(), ids.end(), rng);
    return ids;
}

std::vector<uint32_t> all_ids(size_t n) {
    std::vector<uint32_t> ids(n);
    std::iota(ids.begin(), ids.end(), 0u);
    return ids;
}

// One thread's arrival, counted per node; plain increments (one thread at a time).
struct CountingArrival {
    static inline const uint32_t* base = nullptr;
    static inline std::vector<uint32_t>* totals = nullptr;
    static uint32_t arrive(uint32_t* counter) {
        ++(*totals)[size_t(counter - base)];
        return (*counter)++;
    }
};

// The bug the counters prevent, inverted counters: the first thread to
// arrive goes on before its sibling's box is final, the second stops.
// Arrivals are tracked beside the counters, which the step resets.
struct FirstArrivalContinues {
    static inline const uint32_t* base = nullptr;
    static inline std::vector<uint8_t>* seen = nullptr;
    static uint32_t arrive(uint32_t* counter) {
        uint8_t& s = (*seen)[size_t(counter - base)];
        s ^= 1u;
        return s;  // 1 for the first arrival, 0 for the second
    }
};

// What the device has before a frame's refit: the tree with last frame's
// boxes, the parents from the parents kernel, the moved triangles.
struct DeviceState {
    Bvh bvh;
    std::vector<uint32_t> parents, leaves, arrivals;
    std::vector<Triangle> triangles;
    refit::RefitView view() {
        return {bvh.nodes.data(), parents.data(), bvh.prim_indices.data(), triangles.data(), arrivals.data()};
    }
};

SceneGeometry moved(const SceneGeometry& g, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-0.5f, 0.5f);
    SceneGeometry out = g;
    for (Triangle& t : out.triangles) {
        const Vec3f offset(u(rng), u(rng), u(rng));
        t.v0 = t.v0 + offset;
        t.v1 = t.v1 + offset + Vec3f(u(rng), u(rng), u(rng)) * 0.2f;
        t.v2 = t.v2 + offset;
    }
    return out;
}

// The parents kernel in a shuffled thread order.
DeviceState device_state(const SceneGeometry& start, const SceneGeometry& now, int leaf_size, uint32_t seed) {
    DeviceState d;
    BuildOptions options;
    options.max_leaf_size = leaf_size;
    d.bvh = build_bvh_on_cpu(start.triangles, options);
    const size_t n = d.bvh.nodes.size();
    d.parents.assign(n, 0xdeadbeefu);
    for (uint32_t i : shuffled(all_ids(n), seed)) refit::parent_step(d.bvh.nodes.data(), i, d.parents.data());
    for (uint32_t i = 0; i < n; ++i) {
        if (d.bvh.nodes[i].is_leaf()) d.leaves.push_back(i);
    }
    d.arrivals.assign(n, 0);
    d.triangles = now.triangles;
    return d;
}

Bvh serial_refit(const DeviceState& d) {
    Bvh expected = d.bvh;
    refit_bvh_serial(expected, d.triangles);
    return expected;
}

bool same_nodes(const Bvh& a, const Bvh& b) {
    return a.nodes.size() == b.nodes.size() &&
           std::memcmp(a.nodes.data(), b.nodes.data(), a.nodes.size() * sizeof(BvhNode)) == 0;
}

std::vector<SceneGeometry> scenes() {
    return {test::to_geometry(test::make_icosphere(3)),
            test::make_triangle_soup(4000, 5, {Vec3f(-8.0f), Vec3f(8.0f)}, 0.5f), test::make_nasty_geometry(2)};
}

TEST(BvhRefitDeviceLogic, ParentsEqualThePlans) {
    for (const SceneGeometry& g : scenes()) {
        const DeviceState d = device_state(g, g, 4, 1);
        const RefitPlan plan = make_refit_plan(d.bvh);
        EXPECT_EQ(d.parents, plan.parents);
        EXPECT_EQ(d.leaves, plan.leaves);
    }
}

TEST(BvhRefitDeviceLogic, ShuffledLeafThreadsEqualSerialRefit) {
    for (const SceneGeometry& g : scenes()) {
        for (int leaf_size : {1, 4}) {
            DeviceState d = device_state(g, moved(g, 3), leaf_size, 2);
            const Bvh expected = serial_refit(d);
            std::vector<uint32_t> totals(d.bvh.nodes.size(), 0);
            CountingArrival::base = d.arrivals.data();
            CountingArrival::totals = &totals;
            for (uint32_t seed : {7u, 8u, 9u}) {  // three frames' launches over the same counters
                for (uint32_t leaf : shuffled(d.leaves, seed)) refit::refit_from_leaf<CountingArrival>(d.view(), leaf);
                EXPECT_TRUE(same_nodes(d.bvh, expected)) << "leaf size " << leaf_size << ", seed " << seed;
                for (uint32_t a : d.arrivals) ASSERT_EQ(a, 0u);
            }
            for (size_t i = 0; i < totals.size(); ++i) {
                EXPECT_EQ(totals[i], d.bvh.nodes[i].is_leaf() ? 0u : 6u) << "node " << i;  // two per launch
            }
        }
    }
}

TEST(BvhRefitDeviceLogic, ConcurrentLeafThreadsEqualSerialRefit) {
    for (const SceneGeometry& g : scenes()) {
        DeviceState d = device_state(g, moved(g, 4), 1, 3);
        const Bvh expected = serial_refit(d);
        const std::vector<uint32_t> order = shuffled(d.leaves, 5);
        std::atomic<size_t> next{0};
        std::vector<std::thread> pool;
        const refit::RefitView view = d.view();
        for (int k = 0; k < 8; ++k) {
            pool.emplace_back([&] {
                for (size_t i; (i = next.fetch_add(1)) < order.size();) {
                    refit::refit_from_leaf<karras::AtomicArrival>(view, order[i]);
                }
            });
        }
        for (std::thread& t : pool) t.join();
        EXPECT_TRUE(same_nodes(d.bvh, expected));
        for (uint32_t a : d.arrivals) ASSERT_EQ(a, 0u);
    }
}

TEST(BvhRefitDeviceLogic, FirstArrivalContinuingIsCaught) {
    const SceneGeometry g = test::make_triangle_soup(2000, 6, {Vec3f(-8.0f), Vec3f(8.0f)}, 0.5f);
    DeviceState d = device_state(g, moved(g, 6), 1, 4);
    const Bvh expected = serial_refit(d);
    // The first arrival reads its sibling's stale box from the last frame.
    std::vector<uint8_t> seen(d.arrivals.size(), 0);
    FirstArrivalContinues::base = d.arrivals.data();
    FirstArrivalContinues::seen = &seen;
    for (uint32_t leaf : shuffled(d.leaves, 10)) refit::refit_from_leaf<FirstArrivalContinues>(d.view(), leaf);
    EXPECT_FALSE(same_nodes(d.bvh, expected));
}

TEST(BvhRefitDeviceLogic, SingleLeafTree) {
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    SceneGeometry far = one;
    far.triangles[0] = {Vec3f(4, 4, 4), Vec3f(6, 4, 4), Vec3f(4, 5, 9)};
    DeviceState d = device_state(one, far, 4, 1);
    ASSERT_EQ(d.leaves.size(), 1u);
    EXPECT_EQ(d.parents[0], refit::kNoParent);
    refit::refit_from_leaf<karras::AtomicArrival>(d.view(), 0);
    EXPECT_EQ(d.bvh.nodes[0].bounds.lo, Vec3f(4, 4, 4));
    EXPECT_EQ(d.bvh.nodes[0].bounds.hi, Vec3f(6, 5, 9));
}

}  // namespace
}  // namespace rf
