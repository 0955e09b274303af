// Paged scenes with the geometry cache in device memory
// (backend/cuda/paged_device.cu) against the CPU's PagedEngine on the same
// file: closest hits (primitive, t, u, v) and any hits equal, exactly, with
// device pools of 1, 3, a quarter of the pages and all of them, behind host
// caches smaller than the scene and staging fills of one page or 1 MB; the
// schedule of the CPU engine with a pool of as many slots (iterations,
// pages searched, evictions; within 0.5 %, see below); memory within the budgets; a budget without a
// slot is one line. tests/paged_device_logic_test.cpp checks the same loop
// on the CPU. Skips with a message when no CUDA device is present (fails
// with RAYFORGE_REQUIRE_GPU=1).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "../accel_test_rays.h"
#include "../test_paths.h"
#include "backend/cuda/paged_device.h"
#include "gpu_test_device.h"
#include "ooc/paged_engine.h"
#include "rayforge/core/error.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/ooc/paged_scene.h"

namespace rf {
namespace {

using namespace rf::pack;

struct Fixture {
    std::shared_ptr<const PackFile> file;
    std::vector<Ray> rays;
    size_t host_slot = 0;
    std::vector<Hit> hits;          // PagedEngine's
    std::vector<uint8_t> occluded;  // PagedEngine's
};

// The spheres scene in pages of 256 quads, 30000 rays, and the CPU's answers.
const Fixture& fixture() {
    static const std::unique_ptr<Fixture> f = [] {
        auto out = std::make_unique<Fixture>();
        Scene scene = make_builtin_scene("spheres");
        scene.finalize();
        const std::string path = test::temp_dir("gpu_paged_device") + "/spheres.rfpack";
        PagedWriteOptions options;
        options.quads_per_page = 256;
        convert_to_paged(scene, path, options);
        out->file = std::make_shared<const PackFile>(path);
        for (uint32_t p = 0; p < out->file->header().geometry_pages; ++p)
            out->host_slot = std::max<size_t>(out->host_slot, out->file->directory()[p].raw_bytes);
        out->rays = test::make_rays(SceneGeometry::build(scene), 30000, 9);
        PagedEngine engine(out->file, {size_t(64) << 20, size_t(1) << 20}, 0);
        out->hits.resize(out->rays.size());
        out->occluded.resize(out->rays.size());
        engine.intersect(out->rays, out->hits);
        engine.occluded(out->rays, out->occluded);
        return out;
    }();
    return *f;
}

size_t host_budget_for(uint32_t pages, uint32_t slots, size_t slot_bytes) {
    return size_t(pages) * PageCache::kTableBytesPerPage +
           size_t(slots) * (slot_bytes + PageCache::kBookkeepingBytesPerSlot) + slot_bytes / 2;
}

struct Pools {
    uint32_t device_slots;
    uint32_t host_slots;
    size_t staging_bytes;
};

void expect_same_as_cpu(const Pools& p) {
    const Fixture& f = fixture();
    const uint32_t n = f.file->header().geometry_pages;
    const StagingLayout layout = staging_layout(p.staging_bytes, round_up_16(f.host_slot));
    cuda::DevicePagedBudgets budgets;
    budgets.device_bytes = device_budget_for_slots(n, layout, p.device_slots);
    budgets.host_bytes = host_budget_for(n, p.host_slots, f.host_slot);
    budgets.staging_bytes = p.staging_bytes;
    const std::string what = "device slots " + std::to_string(p.device_slots) + ", host slots " +
                             std::to_string(p.host_slots) + ", staging " + std::to_string(p.staging_bytes);
    cuda::DevicePagedEngine engine(f.file, budgets);
    ASSERT_EQ(engine.device_slot_count(), p.device_slots) << what;
    PagedEngine same_pool(f.file, {host_budget_for(n, p.device_slots, f.host_slot), size_t(1) << 20}, 0);
    for (int loop = 0; loop < 2; ++loop) {  // cold, then warm
        std::vector<Hit> hits(f.rays.size());
        std::vector<uint8_t> occluded(f.rays.size());
        engine.intersect(f.rays, hits);
        engine.occluded(f.rays, occluded);
        std::vector<Hit> cpu_hits(f.rays.size());  // the schedule to compare with, below
        std::vector<uint8_t> cpu_occluded(f.rays.size());
        same_pool.intersect(f.rays, cpu_hits);
        same_pool.occluded(f.rays, cpu_occluded);
        for (size_t i = 0; i < f.rays.size(); ++i) {
            ASSERT_EQ(hits[i].prim, f.hits[i].prim) << what << ", ray " << i;
            ASSERT_EQ(hits[i].t, f.hits[i].t) << what << ", ray " << i;
            ASSERT_EQ(hits[i].u, f.hits[i].u) << what << ", ray " << i;
            ASSERT_EQ(hits[i].v, f.hits[i].v) << what << ", ray " << i;
            ASSERT_EQ(occluded[i], f.occluded[i]) << what << ", ray " << i;
        }
    }
    // The schedule is the CPU's (the CPU replay shows it equal), up to the
    // device's fused multiply-adds in the top grid's walk (paged_traversal.h
    // computes cell planes as lo + i * size, which nvcc contracts): a ray on a
    // cell boundary may start or stop one cell apart, so counts are compared
    // within 0.5 %.
    const cuda::DevicePagedStats& s = engine.stats();
    const EngineStats& cpu = same_pool.stats();
    const auto near = [&](uint64_t device, uint64_t host, const char* name) {
        EXPECT_LE(std::abs(double(device) - double(host)), 0.005 * double(host) + 1.0)
            << what << ": " << name << " " << device << " on the device, " << host << " on the CPU";
    };
    near(s.loop.iterations, cpu.iterations, "iterations");
    near(s.runs, cpu.ray_iterations, "ray runs");
    near(s.cells, cpu.cells, "cells");
    near(s.middle, cpu.middle, "middle nodes");
    near(s.pages, cpu.pages, "pages searched");
    near(s.nodes, cpu.nodes, "page nodes");
    near(s.quads, cpu.quads, "quads");
    near(s.device_pool.evictions, same_pool.geometry_cache().stats().evictions, "evictions");
    EXPECT_EQ(s.loop.pages_staged, s.device_pool.admitted) << what;
    EXPECT_GT(s.loop.fills, 0u) << what;
    EXPECT_LE(engine.device_cache_bytes(), budgets.device_bytes) << what;
    EXPECT_LE(engine.host_cache().memory_bytes(), budgets.host_bytes) << what;
    EXPECT_GT(engine.device_ray_bytes_peak(), 0u) << what;
}

TEST(GpuPagedDevice, HitsEqualPagedEngineWithSmallDevicePools) {
    RF_REQUIRE_DEVICE();
    const uint32_t n = fixture().file->header().geometry_pages;
    for (const Pools& p : {Pools{1, 1, 1}, Pools{1, n / 3, kDefaultStagingBytes}, Pools{3, 2, kDefaultStagingBytes},
                           Pools{3, n / 3, 1}})
        expect_same_as_cpu(p);
}

TEST(GpuPagedDevice, HitsEqualPagedEngineWithLargeDevicePools) {
    RF_REQUIRE_DEVICE();
    const uint32_t n = fixture().file->header().geometry_pages;
    for (const Pools& p : {Pools{n / 4, 2, kDefaultStagingBytes}, Pools{n, 1, kDefaultStagingBytes},
                           Pools{n, n / 3, 1}, Pools{n, n / 3, kDefaultStagingBytes}})
        expect_same_as_cpu(p);
}

// Empty batches, clearing both levels, and a budget that holds no slot.
TEST(GpuPagedDevice, EmptyBatchesClearsAndBudgetErrors) {
    RF_REQUIRE_DEVICE();
    const Fixture& f = fixture();
    cuda::DevicePagedEngine engine(f.file, {});
    engine.intersect({}, {});
    engine.occluded({}, {});
    std::vector<Hit> hits(f.rays.size());
    engine.intersect(f.rays, hits);
    EXPECT_GT(engine.device_cached_count(), 0u);
    engine.clear_caches();
    EXPECT_EQ(engine.device_cached_count(), 0u);
    std::vector<Hit> again(f.rays.size());
    engine.intersect(f.rays, again);
    for (size_t i = 0; i < hits.size(); ++i) ASSERT_EQ(again[i].prim, f.hits[i].prim) << "ray " << i;

    cuda::DevicePagedBudgets tiny;
    tiny.device_bytes = 4096;
    try {
        cuda::DevicePagedEngine refused(f.file, tiny);
        ADD_FAILURE() << "a device budget without a slot was accepted";
    } catch (const Error& e) {
        const std::string m = e.what();
        EXPECT_NE(m.find("holds no slot"), std::string::npos) << m;
        EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
}

}  // namespace
}  // namespace rf
