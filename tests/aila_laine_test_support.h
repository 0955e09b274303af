// What the node-pair traversal tests share (tests/aila_laine_test.cpp,
// tests/aila_laine_fma_test.cpp): warp votes that force speculation and
// yields on the host, host replays of the persistent kernel's schedule
// (backend/cuda/device_tracer.cu: aila_laine_persistent_kernel), and the
// closest-hit comparison with brute force.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "rayforge/math/ray.h"
#include "trace/aila_laine_traversal.h"

namespace rf::test {

// A warp whose other rays never find a leaf: the ray postpones its first leaf
// and walks on until its stack is empty or a second leaf stops it, the most
// speculation the device traversal can ever do.
struct NeverReadyWarp {
    static bool any_searching(bool) { return true; }
    static bool yield_for_refill() { return false; }
};

// A warp whose refill vote fires after every leaf phase (the device's
// dynamic fetch at its most eager) and one where it fires pseudo-randomly,
// both with speculation, so that rays stop and resume mid-traversal.
struct AlwaysRefillWarp {
    static inline uint64_t yields = 0;
    static bool any_searching(bool) { return true; }
    static bool yield_for_refill() {
        ++yields;
        return true;
    }
};
struct RandomRefillWarp {
    static inline uint32_t step = 0;
    static bool any_searching(bool searching) { return searching; }
    static bool yield_for_refill() {
        step = step * 1664525u + 1013904223u;
        return (step >> 28) < 5;  // about a third of the leaf phases
    }
};

// Traces `rays` the way the persistent kernel does, on one host "warp" of
// 32 lanes: idle lanes take the next rays, every lane resumes, finished
// lanes write their result; writes[i] counts the results written for ray i.
template <bool kAnyHit, class Vote, class Traversal = AilaLaineTraversal>
std::vector<Hit> trace_like_persistent_warp(const AilaLaineView& view, const std::vector<Ray>& rays,
                                            std::vector<int>& writes) {
    constexpr int kLanes = 32;
    std::vector<Hit> out(rays.size());
    writes.assign(rays.size(), 0);
    std::vector<typename Traversal::State> state(kLanes);
    std::vector<int64_t> ray_of(kLanes, -1);
    size_t next = 0;
    for (;;) {
        bool any = false;
        for (int lane = 0; lane < kLanes; ++lane) {
            if (ray_of[lane] < 0 && next < rays.size()) {
                ray_of[lane] = int64_t(next);
                Traversal::begin(view, rays[next++], state[lane]);
            }
            if (ray_of[lane] < 0) continue;
            any = true;
            if (Traversal::template resume<kAnyHit, false, Vote>(view, state[lane], nullptr)) {
                out[size_t(ray_of[lane])] = state[lane].hit;
                ++writes[size_t(ray_of[lane])];
                ray_of[lane] = -1;
            }
        }
        if (!any) break;
    }
    return out;
}

inline void expect_same_closest(const Hit& got, const Hit& brute, const Ray& ray) {
    ASSERT_EQ(got.found(), brute.found());
    if (!brute.found()) return;
    if (got.prim != brute.prim) {
        // Another triangle at (almost) the same distance: shared edges, duplicates.
        EXPECT_NEAR(got.t, brute.t, 1e-5f * std::fabs(brute.t)) << "prim " << got.prim << " brute " << brute.prim;
    } else {
        EXPECT_EQ(got.t, brute.t);
        EXPECT_EQ(got.u, brute.u);
        EXPECT_EQ(got.v, brute.v);
    }
    EXPECT_GE(got.t, ray.tmin);
    EXPECT_LE(got.t, ray.tmax);
}

}  // namespace rf::test
