// The device batches (Accel / World ::intersect_on_device, occluded_on_device):
// rays already in device memory, answered in device memory, equal the host
// batches' answers on every kernel, on the default stream and a stream of
// the caller's; host pointers are refused with one clear error; and host
// batches from several threads at once on one world (each call on a scratch
// and stream of its own) equal the same batches one at a time. Skips with a
// message when no CUDA device is present (fails with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <string>
#include <thread>
#include <vector>

#include "../accel_test_rays.h"
#include "backend/cuda/self_test.h"
#include "gpu_test_device.h"
#include "rayforge/core/error.h"
#include "rayforge/world.h"

namespace rf {
namespace {

using cuda::self_test::DeviceBytes;

void expect_same_hits(const std::vector<Hit>& a, const std::vector<Hit>& b) {
    ASSERT_EQ(a.size(), b.size());
    size_t differ = 0;
    for (size_t i = 0; i < a.size(); ++i) differ += a[i].prim != b[i].prim || a[i].t != b[i].t;
    EXPECT_EQ(differ, 0u);
}

TEST(GpuDeviceBatch, DeviceRaysAnswerAsHostBatches) {
    RF_REQUIRE_DEVICE();
    for (GpuKernel kernel : {GpuKernel::Bvh2, GpuKernel::AilaLaine, GpuKernel::Cwbvh}) {
        SCOPED_TRACE(to_string(kernel));
        const auto world = open_world("builtin:spheres", gpu_test::world_on_device(kernel));
        const std::vector<Ray> rays = test::make_rays(world->geometry(), 100000, 3);
        std::vector<Hit> expected(rays.size());
        std::vector<uint8_t> expected_blocked(rays.size());
        world->intersect(rays, expected);
        world->occluded(rays, expected_blocked);

        DeviceBytes device_rays(rays.size() * sizeof(Ray), 0), device_hits(rays.size() * sizeof(Hit), 0),
            device_flags(rays.size(), 0);
        device_rays.upload(rays.data(), rays.size() * sizeof(Ray));
        for (void* stream : {static_cast<void*>(nullptr), device_rays.stream()}) {
            world->intersect_on_device(static_cast<const Ray*>(device_rays.data()), static_cast<Hit*>(device_hits.data()),
                                       rays.size(), stream);
            world->occluded_on_device(static_cast<const Ray*>(device_rays.data()),
                                      static_cast<uint8_t*>(device_flags.data()), rays.size(), stream);
            std::vector<Hit> hits(rays.size());
            std::vector<uint8_t> blocked(rays.size());
            device_hits.download(hits.data(), hits.size() * sizeof(Hit));
            device_flags.download(blocked.data(), blocked.size());
            expect_same_hits(hits, expected);
            EXPECT_EQ(blocked, expected_blocked);
        }
        // Host memory is refused, naming what is wrong.
        std::vector<Hit> host_hits(rays.size());
        try {
            world->intersect_on_device(rays.data(), host_hits.data(), rays.size());
            ADD_FAILURE() << "host rays were accepted";
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("the rays is not"), std::string::npos) << e.what();
        }
    }
}

TEST(GpuDeviceBatch, ConcurrentHostBatchesOnOneWorld) {
    RF_REQUIRE_DEVICE();
    for (GpuKernel kernel : {GpuKernel::AilaLaine, GpuKernel::Cwbvh}) {
        SCOPED_TRACE(to_string(kernel));
        const auto world = open_world("builtin:spheres", gpu_test::world_on_device(kernel));
        constexpr int kThreads = 4;
        std::vector<std::vector<Ray>> rays(kThreads);
        std::vector<std::vector<Hit>> serial(kThreads), concurrent(kThreads);
        for (int t = 0; t < kThreads; ++t) {
            rays[t] = test::make_rays(world->geometry(), 50000 + 1000 * t, 10 + t);
            serial[t].resize(rays[t].size());
            concurrent[t].resize(rays[t].size());
            world->intersect(rays[t], serial[t]);
        }
        std::vector<std::thread> threads;
        for (int t = 0; t < kThreads; ++t) {
            threads.emplace_back([&, t] {
                for (int repeat = 0; repeat < 5; ++repeat) world->intersect(rays[t], concurrent[t]);
            });
        }
        for (std::thread& thread : threads) thread.join();
        for (int t = 0; t < kThreads; ++t) expect_same_hits(concurrent[t], serial[t]);
    }
}

}  // namespace
}  // namespace rf
