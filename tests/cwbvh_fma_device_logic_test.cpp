// The cwbvh-fma kernel's device logic replayed on the CPU
// (backend/cuda/cwbvh_fma_trace.cu): persistent warps with dynamic fetch
// (persistent_fetch_steps.h) around the resumable traversal of
// trace/cwbvh_fma_traversal.h, with the stack top in "shared memory"
// (CwbvhSharedTopStack over a host array interleaved like a block's).
// 32 simulated lanes per warp, several warps drawing from one ray counter:
// a pass ballots the lanes without a ray, the warp takes that many rays
// with one add, each lane takes base + its rank; every lane with a ray
// resumes until done or until the refill vote makes it step aside; a lane
// whose rank falls past the pool exits. Every ray's answer must be written
// exactly once and equal the plain traversal's and brute force's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <vector>

#include "accel/brute_force.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/cwbvh_layout.h"
#include "accel_test_rays.h"
#include "accel_test_scenes.h"
#include "backend/cuda/persistent_fetch_steps.h"
#include "math/random.h"
#include "trace/aila_laine_traversal.h"
#include "trace/cwbvh_fma_traversal.h"
#include "trace/cwbvh_traversal.h"

namespace rf {
namespace {

constexpr int kLanes = 32;

// The device's refill vote (AilaLaineDynamicFetchVote) on a simulated warp:
// step aside when fewer than the threshold of the warp's lanes still hold a
// ray; `random` adds pseudo-random yields so that rays stop and resume at
// many different points of their traversal.
struct ReplayVote {
    const int* lanes_with_rays = nullptr;
    bool random = false;
    uint32_t step = 0;
    uint64_t yields = 0;
    bool yield_for_refill() {
        bool yes = *lanes_with_rays < kAilaLaineDynamicFetchThreshold;
        if (random) yes = yes || (pcg_hash(step++) % 3u) == 0;
        yields += yes;
        return yes;
    }
};

// Postpones about half the time (as tests/cwbvh_test.cpp's random policy):
// postponed triangle groups then sit on the stack across yields.
struct HalfPostpone {
    uint32_t step = 0;
    void begin_iteration() {}
    bool postpone() { return (pcg_hash(0x9E37u ^ step++) & 1u) != 0; }
    void pushed(int) {}
};

struct Replay {
    std::vector<Hit> answers;
    std::vector<int> writes;  // per ray
    uint64_t yields = 0;
    uint64_t fetch_passes = 0;
    size_t max_stack = 0;
};

// `warps` warps of 32 lanes over one ray counter, round robin, one pass each.
template <bool kAnyHit>
Replay replay_persistent(const CwbvhView& bvh, const std::vector<Ray>& rays, int warps, bool random_yields) {
    Replay out;
    out.answers.resize(rays.size());
    out.writes.assign(rays.size(), 0);
    uint32_t counter = 0;  // the global ray counter (atomicAdd)
    const uint32_t count = uint32_t(rays.size());
    struct Lane {
        CwbvhFmaRayState state;
        CwbvhSharedTopStack stack;
        uint32_t ray = 0;
        bool has_ray = false;
        bool exited = false;
    };
    // A block's shared stack tops: entry i of thread t at [i * threads + t].
    const uint32_t threads = uint32_t(warps * kLanes);
    std::vector<detail::CwbvhGroup> shared(size_t(threads) * kCwbvhSharedStackEntries, detail::CwbvhGroup{~0u, ~0u});
    std::vector<Lane> lanes(threads);
    for (uint32_t t = 0; t < threads; ++t) {
        lanes[t].stack.shared = shared.data() + t;
        lanes[t].stack.stride = threads;
    }
    std::vector<int> with_rays(warps, 0);
    std::vector<ReplayVote> votes(warps);
    for (int w = 0; w < warps; ++w) votes[w] = ReplayVote{&with_rays[w], random_yields};
    HalfPostpone postpone;
    detail::CwbvhNoCount none;
    for (bool any_alive = true; any_alive;) {
        any_alive = false;
        for (int w = 0; w < warps; ++w) {
            Lane* warp = lanes.data() + w * kLanes;
            // The ballot of live lanes without a ray, one add, ranks.
            uint32_t needing = 0;
            for (int l = 0; l < kLanes; ++l)
                if (!warp[l].exited && !warp[l].has_ray) needing |= 1u << l;
            if (needing != 0) {
                ++out.fetch_passes;
                const uint32_t base = counter;
                counter += cwbvh_popc(needing);
                for (int l = 0; l < kLanes; ++l) {
                    if (!(needing & (1u << l))) continue;
                    warp[l].ray = persistent_fetch_ray(base, needing, uint32_t(l));
                    if (warp[l].ray >= count) {
                        warp[l].exited = true;
                        continue;
                    }
                    cwbvh_fma_begin(bvh, rays[warp[l].ray], warp[l].state);
                    warp[l].has_ray = true;
                }
            }
            with_rays[w] = 0;
            for (int l = 0; l < kLanes; ++l) with_rays[w] += warp[l].has_ray;
            for (int l = 0; l < kLanes; ++l) {
                Lane& lane = warp[l];
                if (lane.exited) continue;
                any_alive = true;
                if (!lane.has_ray) continue;
                if (cwbvh_fma_resume<kAnyHit>(bvh, lane.state, lane.stack, &none, &postpone, votes[w])) {
                    out.answers[lane.ray] = lane.state.hit;
                    ++out.writes[lane.ray];
                    lane.has_ray = false;
                    --with_rays[w];
                } else {
                    out.max_stack = std::max(out.max_stack, size_t(lane.state.stack_size));
                }
            }
        }
    }
    for (const ReplayVote& v : votes) out.yields += v.yields;
    return out;
}

TEST(CwbvhFmaDeviceLogic, FetchRanksTakeConsecutiveRays) {
    // Every subset pattern of a few lanes: ranks are 0..popc-1 in lane order.
    for (uint32_t needing : {0x1u, 0x80000000u, 0xFFFFFFFFu, 0x0F0F00F1u, 0xA5A5A5A5u}) {
        uint32_t expected = 100;
        for (uint32_t lane = 0; lane < 32; ++lane) {
            if (!(needing & (1u << lane))) continue;
            EXPECT_EQ(persistent_fetch_ray(100, needing, lane), expected++);
        }
        EXPECT_EQ(expected, 100 + cwbvh_popc(needing));
    }
}

TEST(CwbvhFmaDeviceLogic, SharedTopStackSpillsPastItsSharedEntries) {
    std::vector<detail::CwbvhGroup> shared(4 * kCwbvhSharedStackEntries);
    CwbvhSharedTopStack stacks[4];
    for (uint32_t t = 0; t < 4; ++t) {
        stacks[t].shared = shared.data() + t;
        stacks[t].stride = 4;
    }
    for (int i = 0; i < kCwbvhTraversalStackSize; ++i)
        for (uint32_t t = 0; t < 4; ++t) stacks[t].store(i, {uint32_t(i), t});
    for (int i = kCwbvhTraversalStackSize - 1; i >= 0; --i)
        for (uint32_t t = 0; t < 4; ++t) {
            const detail::CwbvhGroup g = stacks[t].load(i);
            EXPECT_EQ(g.base, uint32_t(i));
            EXPECT_EQ(g.hits, t);
        }
    // The shared part is interleaved: thread t's entry i at i * 4 + t.
    EXPECT_EQ(shared[3 * 4 + 2].base, 3u);
    EXPECT_EQ(shared[3 * 4 + 2].hits, 2u);
}

TEST(CwbvhFmaDeviceLogic, PersistentDynamicFetchAnswersEveryRayOnce) {
    const std::vector<SceneGeometry> scenes = {
        test::make_triangle_soup(2500, 41, {Vec3f(-10.0f), Vec3f(10.0f)}, 0.8f),
        test::to_geometry(test::make_icosphere(4)),
        test::make_nasty_geometry(7),
    };
    for (const SceneGeometry& g : scenes) {
        const CwbvhBvh cw = build_cwbvh(build_bvh(g.triangles, BuildOptions{.builder = Builder::Sbvh}), g.triangles);
        const CwbvhView view = cw.view();
        const BruteForceAccel brute(g);
        const std::vector<Ray> rays = test::make_rays(g, 1777, 12);  // not a multiple of the warp
        for (bool random_yields : {false, true}) {
            SCOPED_TRACE(random_yields ? "random yields" : "threshold yields");
            const Replay closest = replay_persistent<false>(view, rays, 3, random_yields);
            const Replay any = replay_persistent<true>(view, rays, 2, random_yields);
            EXPECT_EQ(std::count(closest.writes.begin(), closest.writes.end(), 1), ptrdiff_t(rays.size()));
            EXPECT_EQ(std::count(any.writes.begin(), any.writes.end(), 1), ptrdiff_t(rays.size()));
            EXPECT_GT(closest.yields, 0u);
            for (size_t i = 0; i < rays.size(); ++i) {
                const Hit expected = brute.intersect(rays[i]);
                const Hit plain = cwbvh_fma_intersect(view, rays[i]);
                ASSERT_EQ(closest.answers[i].found(), expected.found()) << i;
                ASSERT_EQ(any.answers[i].found(), expected.found()) << i;
                if (!expected.found()) continue;
                uint32_t got_t, plain_t;
                std::memcpy(&got_t, &closest.answers[i].t, 4);
                std::memcpy(&plain_t, &plain.t, 4);
                EXPECT_EQ(got_t, plain_t) << i;
                EXPECT_EQ(closest.answers[i].t, expected.t) << i;
            }
        }
    }
}

}  // namespace
}  // namespace rf
