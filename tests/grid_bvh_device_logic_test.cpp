// GridBvh / GridBvhSplit on the device (Garanzha 2014, dissertation ch. 4),
// checked on the CPU: the shared __host__ __device__ steps of
// src/accel/bvh/builders/grid_bvh_steps.h run in the device's schedule
// (shuffled thread orders, per-warp atomics, 8 threads per task) must give
// the CPU builder's references, sorted keys, sparse grid, hierarchy, leaf
// groups and, through the host emission, the same Bvh. The leaf finishing
// and canonical emission of grid_bvh_finish_steps.h (one thread per leaf,
// per-level kernels) equal a recursive reference of the CPU's finishing and,
// in shuffled thread orders, give build_grid_bvh's Bvh. Also: the CPU
// builder's output is pinned by hashes taken before its steps were factored out.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "accel/bvh/builders/grid_bvh.h"
#include "accel/bvh/builders/grid_bvh_emit.h"
#include "accel/bvh/builders/grid_bvh_finish_steps.h"
#include "accel/bvh/builders/grid_bvh_partial_triangles.h"
#include "accel/bvh/builders/grid_bvh_sparse_grid.h"
#include "accel/bvh/builders/grid_bvh_steps.h"
#include "accel_test_scenes.h"
#include "bvh_hash.h"
#include "rayforge/accel/accel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

using gridbvh::CellBox;
using gridbvh::GridFrame;
using gridbvh::GridRef;
using gridbvh::NodeRegion;
using gridbvh::SparseGridView;
using gridbvh::SplitTask;
using gridbvh::TaskBins;
using gridbvh::TaskOutcome;

using test::bvh_hash;

// rf::build_grid_bvh with the groups of `options`.
Bvh cpu_build(std::span<const Triangle> tris, const BuildOptions& options, bool split,
              GridBvhStages* stages = nullptr) {
    return build_grid_bvh(tris, bvh_build_config(options), options.grid_bvh, split, stages);
}

SceneGeometry make_diagonal_slivers(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-10.0f, 10.0f);
    SceneGeometry g;
    for (int i = 0; i < count; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        const Vec3f d(1.0f, (i & 1) ? 1.0f : -1.0f, (i & 2) ? 1.0f : -1.0f);
        test::append(g, {a, a + d * 6.0f, a + test::random_direction(rng) * 0.05f});
    }
    return g;
}

struct GoldenScene {
    std::string name;
    SceneGeometry geometry;
};

std::vector<GoldenScene> golden_scenes() {
    std::vector<GoldenScene> s;
    s.push_back({"icosphere", test::to_geometry(test::make_icosphere(4))});
    s.push_back({"soup", test::make_triangle_soup(3000, 7, Box3f{Vec3f(-5.0f), Vec3f(5.0f)}, 0.3f)});
    s.push_back({"nasty", test::make_nasty_geometry(3)});
    s.push_back({"slivers", make_diagonal_slivers(800, 11)});
    SceneGeometry point;
    for (int i = 0; i < 50; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    s.push_back({"one point", std::move(point)});
    SceneGeometry one;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    s.push_back({"one", std::move(one)});
    return s;
}

// Prints the hashes (for re-pinning after an intended change of the builder).
TEST(GridBvhDeviceLogic, CpuBuilderOutputIsPinned) {
    const bool print = std::getenv("RF_PRINT_GRID_BVH_HASHES") != nullptr;
    const std::vector<uint64_t> expected = {
        0xe708e7bfe54d9ce4ull,  // icosphere split 0 budget 0.3
        0xe708e7bfe54d9ce4ull,  // icosphere split 1 budget 0.3
        0xba8cfea40987865full,  // icosphere split 1 budget 2
        0x18970e7f5ef8650cull,  // soup split 0 budget 0.3
        0x18970e7f5ef8650cull,  // soup split 1 budget 0.3
        0x99806c57eccf4523ull,  // soup split 1 budget 2
        0x7760930a304362a7ull,  // nasty split 0 budget 0.3
        0x7760930a304362a7ull,  // nasty split 1 budget 0.3
        0x0da0da75e4314dd4ull,  // nasty split 1 budget 2
        0x0c304612b863da29ull,  // slivers split 0 budget 0.3
        0x0c304612b863da29ull,  // slivers split 1 budget 0.3
        0x04d624799cb80694ull,  // slivers split 1 budget 2
        0xc9d8c4347ce484f5ull,  // one point split 0 budget 0.3
        0xc9d8c4347ce484f5ull,  // one point split 1 budget 0.3
        0xc9d8c4347ce484f5ull,  // one point split 1 budget 2
        0x1d20b241c172dec2ull,  // one split 0 budget 0.3
        0x1d20b241c172dec2ull,  // one split 1 budget 0.3
        0x1d20b241c172dec2ull,  // one split 1 budget 2
    };
    size_t k = 0;
    for (const GoldenScene& scene : golden_scenes()) {
        for (int split = 0; split < 2; ++split) {
            for (const float budget : {0.3f, 2.0f}) {
                if (!split && budget != 0.3f) continue;
                const BuildOptions options{.grid_bvh = {.split_budget = budget}};
                const uint64_t h = bvh_hash(cpu_build(scene.geometry.triangles, options, split != 0));
                if (print) std::printf("        0x%016llxull,  // %s split %d budget %g\n", (unsigned long long)h,
                                       scene.name.c_str(), split, budget);
                if (k < expected.size()) {
                    EXPECT_EQ(expected[k], h) << scene.name << " split " << split << " budget " << budget;
                }
                ++k;
            }
        }
    }
    EXPECT_EQ(k, expected.size());
}


// ---- the device schedule, emulated ----

// Thread ids 0..n-1 in a shuffled order (a kernel's threads in any order).
std::vector<uint32_t> shuffled(size_t n, std::mt19937& rng) {
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::shuffle(order.begin(), order.end(), rng);
    return order;
}

template <class T>
std::vector<T> inclusive_sum(const std::vector<T>& v) {
    std::vector<T> out(v.size());
    T running = 0;
    for (size_t i = 0; i < v.size(); ++i) out[i] = running += v[i];
    return out;
}

// Step 1 as grid_bvh_build.cu runs it: references, the scene box, two passes
// of request / inclusive scan / share / scan / write parts / select.
struct DeviceRefs {
    GridFrame frame;
    std::vector<GridRef> refs;
};

DeviceRefs device_references(std::span<const Triangle> triangles, bool partial, float budget, std::mt19937& rng) {
    const uint32_t n = uint32_t(triangles.size());
    DeviceRefs d;
    d.refs.resize(n);
    for (uint32_t i : shuffled(n, rng)) d.refs[i] = gridbvh::triangle_ref(triangles[i], i);
    Box3f scene;
    for (uint32_t i : shuffled(n, rng)) {
        scene = {gridbvh::vmin(scene.lo, d.refs[i].lo), gridbvh::vmax(scene.hi, d.refs[i].hi)};
    }
    d.frame = GridFrame(scene);
    const float extent = std::max(d.frame.extent.x, std::max(d.frame.extent.y, d.frame.extent.z));
    const float max_width = extent / 128.0f;
    if (!partial || !(max_width > 0.0f) || !(budget > 0.0f)) return d;
    const uint64_t budget_slots = uint64_t(std::floor(double(budget) * double(n)));
    uint64_t used = 0;
    for (int pass = 0; pass < 2 && used < budget_slots; ++pass) {
        const uint64_t available = budget_slots - used;
        const size_t count = d.refs.size();
        std::vector<uint64_t> requests(count);
        for (uint32_t i : shuffled(count, rng)) requests[i] = gridbvh::split_request(d.refs[i], max_width);
        const uint64_t asked = inclusive_sum(requests).back();
        if (asked == 0) break;
        std::vector<uint64_t> slots(count);
        for (uint32_t i : shuffled(count, rng)) {
            slots[i] = uint64_t{gridbvh::split_share(uint32_t(requests[i]), asked, available)} + 1;
        }
        const std::vector<uint64_t> ends = inclusive_sum(slots);
        std::vector<GridRef> parts(ends.back());
        for (uint32_t i : shuffled(count, rng)) {
            const uint32_t splits = gridbvh::split_share(uint32_t(requests[i]), asked, available);
            GridRef* out = parts.data() + (ends[i] - splits - 1);
            if (splits == 0) {
                *out = d.refs[i];
            } else {
                gridbvh::write_parts(triangles[d.refs[i].prim], d.refs[i], splits, d.frame, out);
            }
        }
        std::vector<GridRef> kept;
        for (const GridRef& r : parts) {
            if (r.prim != gridbvh::kInvalidRef) kept.push_back(r);
        }
        used += kept.size() - count;
        d.refs = std::move(kept);
    }
    return d;
}

// Steps 2-4: keys sorted once (a stable sort, as CUB's radix sort), Grid0 by
// flags, scans and a shuffled scatter, the count-only levels.
struct DeviceGrid {
    std::vector<uint32_t> keys, ids;
    std::vector<uint32_t> top_index, top_key, top_begin, top_cells, fine_begin;
    std::vector<uint64_t> top_mask;
    std::vector<uint32_t> dense[4];
    [[nodiscard]] SparseGridView view() const {
        return {top_index.data(), top_begin.data(), top_cells.data(), top_mask.data(), fine_begin.data(),
                {dense[0].data(), dense[1].data(), dense[2].data(), dense[3].data()}};
    }
};

DeviceGrid device_grid(const DeviceRefs& d, std::mt19937& rng) {
    const uint32_t n = uint32_t(d.refs.size());
    DeviceGrid g;
    std::vector<uint32_t> keys(n);
    for (uint32_t i : shuffled(n, rng)) keys[i] = gridbvh::fine_key(d.frame, d.refs[i].centroid());
    g.ids.resize(n);
    std::iota(g.ids.begin(), g.ids.end(), 0u);
    std::stable_sort(g.ids.begin(), g.ids.end(), [&](uint32_t a, uint32_t b) { return keys[a] < keys[b]; });
    g.keys.resize(n);
    for (uint32_t i = 0; i < n; ++i) g.keys[i] = keys[g.ids[i]];
    std::vector<uint32_t> top_flags(n), fine_flags(n);
    for (uint32_t i : shuffled(n, rng)) {
        top_flags[i] = i == 0 || (g.keys[i] >> 9) != (g.keys[i - 1] >> 9);
        fine_flags[i] = i == 0 || g.keys[i] != g.keys[i - 1];
    }
    const std::vector<uint32_t> top_rank = inclusive_sum(top_flags), fine_rank = inclusive_sum(fine_flags);
    const uint32_t occupied = top_rank.back(), cells = fine_rank.back();
    g.top_key.assign(occupied, 0xdeadbeefu);
    g.top_begin.assign(occupied + 1, 0xdeadbeefu);
    g.top_cells.assign(occupied + 1, 0xdeadbeefu);
    g.fine_begin.assign(cells + 1, 0xdeadbeefu);
    g.top_mask.assign(size_t{occupied} * gridbvh::kMaskWords, 0);
    g.top_begin[occupied] = n;
    g.top_cells[occupied] = cells;
    g.fine_begin[cells] = n;
    for (uint32_t i : shuffled(n, rng)) {
        if (!(i == 0 || fine_rank[i] != fine_rank[i - 1])) continue;
        const uint32_t m = top_rank[i] - 1, c = fine_rank[i] - 1;
        g.fine_begin[c] = i;
        const uint32_t sub = g.keys[i] & uint32_t(gridbvh::kSubCells - 1);
        g.top_mask[size_t{m} * gridbvh::kMaskWords + sub / 64] |= uint64_t{1} << (sub % 64);
        if (i == 0 || top_rank[i] != top_rank[i - 1]) {
            g.top_begin[m] = i;
            g.top_key[m] = g.keys[i] >> 9;
            g.top_cells[m] = c;
        }
    }
    g.top_index.assign(size_t(gridbvh::kTopRes) * gridbvh::kTopRes * gridbvh::kTopRes, gridbvh::kEmptyCell);
    for (uint32_t m : shuffled(occupied, rng)) g.top_index[g.top_key[m]] = m;
    for (int k = 0; k < 4; ++k) {
        const size_t res = size_t(gridbvh::kFineRes) >> (4 + k);
        g.dense[k].assign(res * res * res, 0);
    }
    for (uint32_t m : shuffled(occupied, rng)) {
        const uint32_t key = g.top_key[m], t = gridbvh::kTopRes, res = t / 2;
        const uint32_t x = key % t, y = (key / t) % t, z = key / (t * t);
        g.dense[0][(x >> 1) + res * ((y >> 1) + res * (z >> 1))] += g.top_begin[m + 1] - g.top_begin[m];
    }
    for (int k = 1; k < 4; ++k) {
        const uint32_t res = uint32_t(gridbvh::kFineRes) >> (4 + k), child_res = 2 * res;
        for (uint32_t c : shuffled(size_t{res} * res * res, rng)) {
            const uint32_t x = c % res, y = (c / res) % res, z = c / (res * res);
            uint32_t sum = 0;
            for (uint32_t dd = 0; dd < 8; ++dd) {
                const uint32_t cx = 2 * x + (dd & 1), cy = 2 * y + ((dd >> 1) & 1), cz = 2 * z + (dd >> 2);
                sum += g.dense[k - 1][cx + child_res * (cy + child_res * cz)];
            }
            g.dense[k][c] = sum;
        }
    }
    return g;
}

// Step 5: split_level_kernel. Warps of 4 tasks are scheduled in a shuffled
// order; a task's 8 threads visit their slices of its cells in a shuffled
// order into shared bins (the atomics: add, min, max); one packed add per
// warp places its children and leaves.
GridHierarchy device_hierarchy(DeviceRefs&& d, const DeviceGrid& g, uint32_t leaf_size, std::mt19937& rng,
                               int slices = 8) {
    const uint32_t n = uint32_t(d.refs.size());
    const SparseGridView view = g.view();
    GridHierarchy h;
    h.frame = d.frame;
    const SplitTask root = gridbvh::root_task(n);
    h.hnodes.assign(2 * size_t{n} - 1, 0xdeadbeefu);
    h.regions.resize(2 * size_t{n} - 1);
    h.regions[0] = NodeRegion{root.box, root.level};
    std::vector<SplitTask> queue{root}, next;
    h.level_offset = {0};
    uint32_t leaf_count = 0;
    while (!queue.empty()) {
        const uint32_t count = uint32_t(queue.size());
        const uint32_t next_base = h.level_offset.back() + count;
        h.level_offset.push_back(next_base);
        uint32_t split_counter = 0, leaf_counter = 0;
        const uint32_t warps = (count + 3) / 4;
        std::vector<TaskOutcome> outcomes(count);
        next.assign(size_t{count} * 2, SplitTask{});
        size_t splits_total = 0;
        for (uint32_t w : shuffled(warps, rng)) {
            bool split[4] = {}, leaf[4] = {};
            for (uint32_t t = 0; t < 4; ++t) {
                const uint32_t at = 4 * w + t;
                if (at >= count) continue;
                auto scan = [&](int level, const CellBox& box, TaskBins& bins) {
                    bins.clear();
                    for (uint32_t sub : shuffled(size_t(slices), rng)) {
                        gridbvh::for_each_cell(
                            view, level, box,
                            [&](int x, int y, int z, uint32_t c) {
                                bins.bins[0][x - box.lo[0]].add(x, y, z, c);
                                bins.bins[1][y - box.lo[1]].add(x, y, z, c);
                                bins.bins[2][z - box.lo[2]].add(x, y, z, c);
                            },
                            int(sub), slices);
                    }
                };
                outcomes[at] = gridbvh::process_task(queue[at], leaf_size, d.frame, scan);
                split[t] = outcomes[at].split;
                leaf[t] = !outcomes[at].split;
            }
            // One packed atomicAdd per warp, then the lanes' prefix counts.
            uint32_t split_slot = split_counter, leaf_slot = leaf_counter;
            for (uint32_t t = 0; t < 4; ++t) {
                split_counter += split[t];
                leaf_counter += leaf[t];
            }
            for (uint32_t t = 0; t < 4; ++t) {
                const uint32_t at = 4 * w + t;
                if (at >= count) continue;
                const TaskOutcome& o = outcomes[at];
                const uint32_t node = o.left.node;
                if (o.split) {
                    const uint32_t pair = next_base + 2 * split_slot;
                    h.hnodes[node] = pair;
                    SplitTask left = o.left, right = o.right;
                    left.node = pair;
                    right.node = pair + 1;
                    h.regions[pair] = NodeRegion{left.box, left.level};
                    h.regions[pair + 1] = NodeRegion{right.box, right.level};
                    next[2 * split_slot] = left;
                    next[2 * split_slot + 1] = right;
                    ++split_slot;
                    ++splits_total;
                } else {
                    const uint32_t l = leaf_count + leaf_slot++;
                    h.hnodes[node] = gridbvh::kLeafBit | l;
                    if (h.leaves.size() <= l) h.leaves.resize(l + 1);
                    h.leaves[l] = o.left;
                }
            }
        }
        leaf_count += leaf_counter;
        next.resize(2 * splits_total);
        queue.swap(next);
    }
    h.hnodes.resize(h.level_offset.back());
    h.regions.resize(h.level_offset.back());
    h.refs = std::move(d.refs);
    return h;
}

// Step 6: leaf_of_kernel (shuffled), the stable sort of (leaf, reference),
// leaf_begin_kernel (shuffled).
void group_by_leaf(GridHierarchy& h, std::mt19937& rng) {
    const uint32_t n = uint32_t(h.refs.size()), leaf_count = uint32_t(h.leaves.size());
    std::vector<uint32_t> leaf_of(n);
    for (uint32_t i : shuffled(n, rng)) {
        leaf_of[i] = gridbvh::leaf_of_reference(h.hnodes.data(), h.regions.data(), h.frame, h.refs[i]);
    }
    h.leaf_refs.resize(n);
    std::iota(h.leaf_refs.begin(), h.leaf_refs.end(), 0u);
    std::stable_sort(h.leaf_refs.begin(), h.leaf_refs.end(), [&](uint32_t a, uint32_t b) { return leaf_of[a] < leaf_of[b]; });
    std::vector<uint32_t> sorted(n);
    for (uint32_t i = 0; i < n; ++i) sorted[i] = leaf_of[h.leaf_refs[i]];
    h.leaf_begin.assign(size_t{leaf_count} + 1, 0xdeadbeefu);
    for (uint32_t i : shuffled(n, rng)) {
        if (i == 0 || sorted[i] != sorted[i - 1]) {
            for (uint32_t l = i == 0 ? 0 : sorted[i - 1] + 1; l <= sorted[i]; ++l) h.leaf_begin[l] = i;
        }
        if (i == n - 1) {
            for (uint32_t l = sorted[i] + 1; l <= leaf_count; ++l) h.leaf_begin[l] = n;
        }
    }
}

bool same_bvh(const Bvh& a, const Bvh& b) { return bvh_hash(a) == bvh_hash(b) && a.nodes.size() == b.nodes.size(); }

// The CPU builder's frame: its sequential scene-box reduction.
GridFrame cpu_frame(const std::vector<GridRef>& refs) {
    Box3f scene;
    for (const GridRef& r : refs) scene = {gridbvh::vmin(scene.lo, r.lo), gridbvh::vmax(scene.hi, r.hi)};
    return GridFrame(scene);
}

bool same_refs(const std::vector<GridRef>& a, const std::vector<GridRef>& b) {
    return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(GridRef)) == 0);
}

TEST(GridBvhDeviceLogic, ReferencesAfterSplittingEqualCpuWithinTheBudget) {
    std::mt19937 rng(1);
    for (const GoldenScene& scene : golden_scenes()) {
        const std::span<const Triangle> tris = scene.geometry.triangles;
        for (const float budget : {0.0f, 0.05f, 0.3f, 2.0f, 10.0f}) {
            const std::vector<GridRef> whole = gridbvh::make_triangle_refs(tris);
            const GridFrame frame = cpu_frame(whole);
            const std::vector<GridRef> cpu = gridbvh::split_into_partial_triangles(tris, whole, frame, budget);
            const DeviceRefs dev = device_references(tris, true, budget, rng);
            EXPECT_EQ(0, std::memcmp(&frame, &dev.frame, sizeof frame)) << scene.name;
            EXPECT_TRUE(same_refs(cpu, dev.refs)) << scene.name << " budget " << budget << ": " << cpu.size() << " vs "
                                                  << dev.refs.size();
            EXPECT_LE(dev.refs.size() - tris.size(), uint64_t(std::floor(double(budget) * double(tris.size()))))
                << scene.name << " budget " << budget;
        }
    }
}

TEST(GridBvhDeviceLogic, SplittingUsesTheBudgetOnTheLongestReferences) {
    // 10 long triangles among 90 small ones: the budget of 0.3 * 100 = 30
    // splits goes to the long ones, each getting the CPU's rounded-down share.
    SceneGeometry g;
    for (int i = 0; i < 90; ++i) {
        const Vec3f c(float(i % 10), float(i / 10), 0.0f);
        test::append(g, {c, c + Vec3f(0.01f, 0, 0), c + Vec3f(0, 0.01f, 0)});
    }
    for (int i = 0; i < 10; ++i) {
        const Vec3f a(0.0f, float(i), 1.0f);
        test::append(g, {a, a + Vec3f(9.0f, 0, 0), a + Vec3f(0, 0.01f, 0)});
    }
    std::mt19937 rng(2);
    const DeviceRefs dev = device_references(g.triangles, true, 0.3f, rng);
    const std::vector<GridRef> whole = gridbvh::make_triangle_refs(g.triangles);
    const std::vector<GridRef> cpu = gridbvh::split_into_partial_triangles(g.triangles, whole, cpu_frame(whole), 0.3f);
    EXPECT_TRUE(same_refs(cpu, dev.refs));
    EXPECT_GT(dev.refs.size(), g.triangles.size());
    EXPECT_LE(dev.refs.size(), g.triangles.size() + 30);
    for (const GridRef& r : dev.refs) EXPECT_TRUE(r.prim >= 90 || r.prim == uint32_t(&r - dev.refs.data()));
}

TEST(GridBvhDeviceLogic, SortedKeysAndSparseGridEqualCpu) {
    std::mt19937 rng(3);
    for (const GoldenScene& scene : golden_scenes()) {
        for (const bool split : {false, true}) {
            DeviceRefs dev = device_references(scene.geometry.triangles, split, 2.0f, rng);
            const DeviceGrid g = device_grid(dev, rng);
            gridbvh::SparseGrid cpu;
            cpu.build(dev.refs, dev.frame);
            const std::string what = scene.name + (split ? " split" : "");
            auto same = [](auto span, const auto& vec) { return std::equal(span.begin(), span.end(), vec.begin(), vec.end()); };
            EXPECT_TRUE(same(cpu.sorted_refs(), g.ids)) << what;
            EXPECT_TRUE(same(cpu.top_index(), g.top_index)) << what;
            EXPECT_TRUE(same(cpu.top_keys(), g.top_key)) << what;
            EXPECT_TRUE(same(cpu.top_begin(), g.top_begin)) << what;
            EXPECT_TRUE(same(cpu.top_cells(), g.top_cells)) << what;
            EXPECT_TRUE(same(cpu.top_mask(), g.top_mask)) << what;
            EXPECT_TRUE(same(cpu.fine_begin(), g.fine_begin)) << what;
            for (int k = 0; k < 4; ++k) EXPECT_TRUE(same(cpu.dense(k), g.dense[k])) << what << " Grid" << 4 + k;
            EXPECT_EQ(cpu.occupied_top_cells(), g.top_key.size()) << what;
        }
    }
}

// The whole device schedule, then the host half, gives build_grid_bvh's BVH.
Bvh device_build(std::span<const Triangle> tris, const BuildOptions& options, bool split, std::mt19937& rng,
                 GridBvhStages* stages = nullptr, int slices = 8) {
    DeviceRefs dev = device_references(tris, split, options.grid_bvh.split_budget, rng);
    const DeviceGrid g = device_grid(dev, rng);
    GridHierarchy h = device_hierarchy(std::move(dev), g, uint32_t(std::max(1, options.max_leaf_size)), rng, slices);
    group_by_leaf(h, rng);
    return emit_grid_bvh_hierarchy(tris, bvh_build_config(options), split, std::move(h), stages);
}

TEST(GridBvhDeviceLogic, TaskQueueHierarchyGivesTheCpuBvh) {
    for (uint32_t seed : {4u}) {
        std::mt19937 rng(seed);
        for (const GoldenScene& scene : golden_scenes()) {
            for (const bool split : {false, true}) {
                for (const int leaf : {1, 4}) {
                    const BuildOptions options{.max_leaf_size = leaf, .grid_bvh = {.split_budget = 2.0f}};
                    GridBvhStages cpu_stages, dev_stages;
                    const Bvh cpu = cpu_build(scene.geometry.triangles, options, split, &cpu_stages);
                    const Bvh dev = device_build(scene.geometry.triangles, options, split, rng, &dev_stages);
                    EXPECT_TRUE(same_bvh(cpu, dev)) << scene.name << (split ? " split" : "") << " leaf " << leaf;
                    EXPECT_EQ(cpu_stages.references, dev_stages.references) << scene.name;
                    EXPECT_EQ(cpu_stages.hierarchy_leaves, dev_stages.hierarchy_leaves) << scene.name;
                    EXPECT_EQ(cpu_stages.large_leaves, dev_stages.large_leaves) << scene.name;
                }
            }
        }
    }
}

TEST(GridBvhDeviceLogic, OneThreadOrEightPerTaskAgree) {
    std::mt19937 rng(6);
    const SceneGeometry soup = test::make_triangle_soup(2000, 9, Box3f{Vec3f(-1.0f), Vec3f(1.0f)}, 0.05f);
    const BuildOptions options{};
    const Bvh cpu = cpu_build(soup.triangles, options, false);
    for (const int slices : {1, 3, 8, 32}) {
        EXPECT_TRUE(same_bvh(cpu, device_build(soup.triangles, options, false, rng, nullptr, slices))) << slices;
    }
}

TEST(GridBvhDeviceLogic, DegenerateInputs) {
    std::mt19937 rng(7);
    GridHierarchy empty;
    EXPECT_TRUE(emit_grid_bvh_hierarchy({}, BvhBuildConfig{}, false, std::move(empty)).nodes.empty());
    SceneGeometry one, point;
    test::append(one, {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(0, 1, 0)});
    for (int i = 0; i < 1000; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    for (const SceneGeometry* g : {&one, &point}) {
        for (const bool split : {false, true}) {
            const Bvh cpu = cpu_build(g->triangles, BuildOptions{}, split);
            EXPECT_TRUE(same_bvh(cpu, device_build(g->triangles, BuildOptions{}, split, rng)));
        }
    }
}

TEST(GridBvhDeviceLogic, MalformedHierarchyIsRejected) {
    std::mt19937 rng(8);
    const SceneGeometry soup = test::make_triangle_soup(200, 10, Box3f{Vec3f(-1.0f), Vec3f(1.0f)}, 0.05f);
    DeviceRefs dev = device_references(soup.triangles, false, 0.0f, rng);
    const DeviceGrid g = device_grid(dev, rng);
    GridHierarchy h = device_hierarchy(std::move(dev), g, 4, rng);
    ASSERT_GT(h.level_offset.size(), 2u);
    GridHierarchy bad_link = h;
    bad_link.hnodes[0] = uint32_t(bad_link.hnodes.size());  // the root's children past the end
    EXPECT_THROW(emit_grid_bvh_hierarchy(soup.triangles, BvhBuildConfig{}, false, std::move(bad_link)), Error);
    GridHierarchy bad_leaf = h;
    bad_leaf.hnodes.back() = gridbvh::kLeafBit | uint32_t(bad_leaf.leaves.size());
    EXPECT_THROW(emit_grid_bvh_hierarchy(soup.triangles, BvhBuildConfig{}, false, std::move(bad_leaf)), Error);
    GridHierarchy bad_groups = h;
    group_by_leaf(bad_groups, rng);
    bad_groups.leaf_begin.back() -= 1;  // a reference left out
    EXPECT_THROW(emit_grid_bvh_hierarchy(soup.triangles, BvhBuildConfig{}, false, std::move(bad_groups)), Error);
    // Grouped by the host or as the device does: the same BVH.
    GridHierarchy grouped = h;
    group_by_leaf(grouped, rng);
    const uint64_t expected = bvh_hash(cpu_build(soup.triangles, BuildOptions{}, false));
    EXPECT_EQ(expected, bvh_hash(emit_grid_bvh_hierarchy(soup.triangles, BvhBuildConfig{}, false, std::move(h))));
    EXPECT_EQ(expected, bvh_hash(emit_grid_bvh_hierarchy(soup.triangles, BvhBuildConfig{}, false, std::move(grouped))));
}

// ---- leaf finishing and emission on the device (grid_bvh_finish_steps.h) ----

using gridbvh::FinishOptions;
using gridbvh::kDeviceFinishRefs;
using gridbvh::LeafSummary;

// The CPU builder's leaf finishing as it was written before the shared
// steps, recursive and with the standard algorithms (stable_partition,
// clamp, Box3f::surface_area, a full std::sort for the median): the
// reference the shared iterative steps must reproduce.
struct RecursiveFinish {
    FinishOptions o;
    std::vector<BvhNode> nodes;
    std::vector<uint32_t> prims;

    static uint32_t split_binned(GridRef* refs, uint32_t count, const Box3f& centroids, float& cost) {
        const Vec3f extent = centroids.extent();
        int best_axis = -1, best_bin = 0;
        float best_cost = 0.0f;
        for (int a = 0; a < 3; ++a) {
            if (!(extent[a] > 0.0f)) continue;
            const float scale = 8.0f * (1.0f - 0x1p-20f) / extent[a];
            Box3f box[8];
            uint32_t n_in[8] = {};
            for (uint32_t i = 0; i < count; ++i) {
                const int b = std::clamp(int((refs[i].centroid()[a] - centroids.lo[a]) * scale), 0, 7);
                box[b] = {gridbvh::vmin(box[b].lo, refs[i].lo), gridbvh::vmax(box[b].hi, refs[i].hi)};
                ++n_in[b];
            }
            float right_area[8];
            uint32_t right_count[8];
            Box3f acc;
            uint32_t n = 0;
            for (int i = 7; i > 0; --i) {
                acc = {gridbvh::vmin(acc.lo, box[i].lo), gridbvh::vmax(acc.hi, box[i].hi)};
                n += n_in[i];
                right_area[i] = acc.surface_area();
                right_count[i] = n;
            }
            acc = Box3f{};
            n = 0;
            for (int i = 1; i < 8; ++i) {
                acc = {gridbvh::vmin(acc.lo, box[i - 1].lo), gridbvh::vmax(acc.hi, box[i - 1].hi)};
                n += n_in[i - 1];
                if (n == 0 || right_count[i] == 0) continue;
                const float c = acc.surface_area() * float(n) + right_area[i] * float(right_count[i]);
                if (best_axis < 0 || c < best_cost) {
                    best_axis = a;
                    best_bin = i;
                    best_cost = c;
                }
            }
        }
        if (best_axis < 0) return 0;
        cost = best_cost;
        const float scale = 8.0f * (1.0f - 0x1p-20f) / extent[best_axis];
        return uint32_t(std::stable_partition(refs, refs + count, [&](const GridRef& r) {
                            return std::clamp(int((r.centroid()[best_axis] - centroids.lo[best_axis]) * scale), 0, 7) <
                                   best_bin;
                        }) -
                        refs);
    }
    static void bounds(const GridRef* refs, uint32_t count, Box3f& b, Box3f& c) {
        b = c = Box3f{};
        for (uint32_t i = 0; i < count; ++i) {
            b = {gridbvh::vmin(b.lo, refs[i].lo), gridbvh::vmax(b.hi, refs[i].hi)};
            c = {gridbvh::vmin(c.lo, refs[i].centroid()), gridbvh::vmax(c.hi, refs[i].centroid())};
        }
    }
    bool cheaper_as_leaf(float area, float cost, uint32_t count) const {
        return o.traversal_cost * area + o.intersection_cost * cost >= o.intersection_cost * area * float(count);
    }
    void build(GridRef* refs, uint32_t count, int depth, uint32_t node) {
        Box3f b, c;
        bounds(refs, count, b, c);
        nodes[node].bounds = b;
        float cost = 0.0f;
        uint32_t mid = count > 1 ? split_binned(refs, count, c, cost) : 0;
        const bool no_split = mid == 0 || mid == count;
        if (count <= o.max_leaf_size && (no_split || cheaper_as_leaf(b.surface_area(), cost, count))) {
            nodes[node].first = uint32_t(prims.size());
            nodes[node].count = count;
            for (uint32_t i = 0; i < count; ++i) prims.push_back(refs[i].prim);
            return;
        }
        if (no_split || depth + 1 + gridbvh::median_levels(std::max(mid, count - mid), o.max_leaf_size) > kBvhMaxDepth) {
            mid = count / 2;
            if (c.extent().x > 0.0f || c.extent().y > 0.0f || c.extent().z > 0.0f) {
                const int axis = c.largest_axis();
                std::sort(refs, refs + count, [axis](const GridRef& x, const GridRef& y) {
                    const float cx = x.lo[axis] + x.hi[axis], cy = y.lo[axis] + y.hi[axis];
                    return cx < cy || (cx == cy && x.prim < y.prim);
                });
            }
        }
        const uint32_t pair = uint32_t(nodes.size());
        nodes.resize(pair + 2);
        nodes[node].first = pair;
        nodes[node].count = 0;
        build(refs, mid, depth + 1, pair);
        build(refs + mid, count - mid, depth + 1, pair + 1);
    }
    // The leaf over references `ids` of `all`.
    LeafSummary finish(std::vector<uint32_t> ids, const std::vector<GridRef>& all, int depth) {
        std::sort(ids.begin(), ids.end());
        std::vector<GridRef> refs;
        for (uint32_t id : ids) refs.push_back(all[id]);
        std::stable_sort(refs.begin(), refs.end(), [](const GridRef& a, const GridRef& b) { return a.prim < b.prim; });
        size_t out = 0;
        for (size_t i = 0; i < refs.size(); ++i) {
            if (out > 0 && refs[out - 1].prim == refs[i].prim) {
                refs[out - 1].lo = gridbvh::vmin(refs[out - 1].lo, refs[i].lo);
                refs[out - 1].hi = gridbvh::vmax(refs[out - 1].hi, refs[i].hi);
            } else {
                refs[out++] = refs[i];
            }
        }
        refs.resize(out);
        const uint32_t count = uint32_t(out);
        nodes.clear();
        prims.clear();
        bool keep = count <= o.max_leaf_size;
        if (keep && count > 1) {
            Box3f b, c;
            bounds(refs.data(), count, b, c);
            float cost = 0.0f;
            const uint32_t mid = split_binned(refs.data(), count, c, cost);
            keep = mid == 0 || mid == count || cheaper_as_leaf(b.surface_area(), cost, count);
        }
        if (keep) {
            Box3f b, c;
            bounds(refs.data(), count, b, c);
            for (const GridRef& r : refs) prims.push_back(r.prim);
            return LeafSummary{b, 1, count};
        }
        nodes.resize(1);
        build(refs.data(), count, depth, 0);
        return LeafSummary{nodes[0].bounds, uint32_t(nodes.size()), count};
    }
};

bool same_bytes(const void* a, const void* b, size_t bytes) { return bytes == 0 || std::memcmp(a, b, bytes) == 0; }

// `count` references over a small pool of triangles (parts of one triangle
// recur), with boxes from one of several families: random, all equal
// (coincident centroids), a few distinct positions, or slivers on one axis.
std::vector<GridRef> random_leaf_refs(uint32_t count, std::mt19937& rng) {
    std::uniform_real_distribution<float> u(-5.0f, 5.0f), s(0.0f, 0.5f);
    const int family = int(rng() % 4);
    const uint32_t pool = 1 + rng() % (2 * count);
    std::vector<GridRef> refs(count);
    const Vec3f fixed(u(rng), u(rng), u(rng));
    for (GridRef& r : refs) {
        Vec3f lo(u(rng), u(rng), u(rng));
        if (family == 1) lo = fixed;
        if (family == 2) lo = Vec3f(float(rng() % 3), 0.0f, float(rng() % 2));
        if (family == 3) lo = Vec3f(u(rng), 1.0f, 1.0f);
        const Vec3f size = family == 1 ? Vec3f(0.25f) : Vec3f(s(rng), s(rng), s(rng));
        r = GridRef{lo, uint32_t(rng() % pool), lo + size, 0};
    }
    return refs;
}

FinishOptions random_finish_options(std::mt19937& rng) {
    const float costs[][2] = {{1.0f, 1.0f}, {1.0f, 2.0f}, {3.0f, 1.0f}, {0.5f, 1.5f}};
    const auto& c = costs[rng() % 4];
    return FinishOptions{1 + uint32_t(rng() % 8), c[0], c[1]};
}

TEST(GridBvhDeviceLogic, SharedLeafFinishingEqualsTheRecursiveCpuFinishing) {
    std::mt19937 rng(21);
    size_t trees = 0, medians_near_limit = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        const uint32_t count = 1 + uint32_t(rng() % kDeviceFinishRefs);
        const std::vector<GridRef> all = random_leaf_refs(count, rng);
        std::vector<uint32_t> ids(count);
        std::iota(ids.begin(), ids.end(), 0u);
        std::shuffle(ids.begin(), ids.end(), rng);  // the device's group order is free
        const FinishOptions options = random_finish_options(rng);
        const int depth = trial % 3 == 0 ? kBvhMaxDepth - int(rng() % 4) : int(rng() % kBvhMaxDepth);
        RecursiveFinish cpu{options, {}, {}};
        const LeafSummary expected = cpu.finish(ids, all, depth);
        std::vector<BvhNode> nodes(2 * count, BvhNode{Box3f{}, 0xdeadbeefu, 0xdeadbeefu});
        std::vector<uint32_t> prims(count, 0xdeadbeefu);
        const LeafSummary got =
            gridbvh::finish_small_leaf(all.data(), ids.data(), count, depth, options, nodes.data(), prims.data());
        ASSERT_TRUE(same_bytes(&expected, &got, sizeof got)) << "trial " << trial;
        ASSERT_TRUE(same_bytes(cpu.prims.data(), prims.data(), cpu.prims.size() * sizeof(uint32_t))) << "trial " << trial;
        if (got.node_count > 1) {
            ++trees;
            medians_near_limit += depth + 2 > kBvhMaxDepth;
            ASSERT_EQ(cpu.nodes.size(), got.node_count);
            ASSERT_TRUE(same_bytes(cpu.nodes.data(), nodes.data(), cpu.nodes.size() * sizeof(BvhNode))) << "trial " << trial;
        }
    }
    EXPECT_GT(trees, 500u);
    EXPECT_GT(medians_near_limit, 50u);
}

// The sort of the median on large ranges, as the CPU builder runs it.
struct StdSortOnAxis {
    void operator()(GridRef* refs, uint32_t count, int axis) const {
        std::sort(refs, refs + count, [axis](const GridRef& a, const GridRef& b) { return gridbvh::median_before(a, b, axis); });
    }
};

// The shared iterative build in growable buffers (any leaf size).
LeafSummary finish_any_leaf(const std::vector<GridRef>& all, std::vector<uint32_t> ids, int depth, const FinishOptions& o,
                            std::vector<BvhNode>& nodes, std::vector<uint32_t>& prims) {
    const uint32_t count = uint32_t(ids.size());
    std::sort(ids.begin(), ids.end());
    std::vector<GridRef> refs(count), scratch(count);
    std::vector<gridbvh::LocalTask> stack(count + 1);
    for (uint32_t i = 0; i < count; ++i) refs[i] = all[ids[i]];
    nodes.assign(2 * size_t{count}, BvhNode{});
    prims.assign(count, 0u);
    return gridbvh::finish_gathered_leaf(refs.data(), count, depth, o, scratch.data(), stack.data(), nodes.data(),
                                         prims.data(), StdSortOnAxis{});
}

TEST(GridBvhDeviceLogic, SharedIterativeBuildEqualsTheRecursionOnLargeLeaves) {
    std::mt19937 rng(22);
    for (const uint32_t count : {65u, 300u, 2000u, 9000u}) {
        for (int trial = 0; trial < 3; ++trial) {
            const std::vector<GridRef> all = random_leaf_refs(count, rng);
            std::vector<uint32_t> ids(count);
            std::iota(ids.begin(), ids.end(), 0u);
            std::shuffle(ids.begin(), ids.end(), rng);
            const FinishOptions options = random_finish_options(rng);
            const int depth = trial == 0 ? kBvhMaxDepth - 12 : trial * 5;
            RecursiveFinish cpu{options, {}, {}};
            const LeafSummary expected = cpu.finish(ids, all, depth);
            std::vector<BvhNode> nodes;
            std::vector<uint32_t> prims;
            const LeafSummary got = finish_any_leaf(all, ids, depth, options, nodes, prims);
            ASSERT_TRUE(same_bytes(&expected, &got, sizeof got)) << count << " trial " << trial;
            EXPECT_TRUE(same_bytes(cpu.prims.data(), prims.data(), cpu.prims.size() * sizeof(uint32_t))) << count;
            if (got.node_count > 1) {
                EXPECT_TRUE(same_bytes(cpu.nodes.data(), nodes.data(), cpu.nodes.size() * sizeof(BvhNode))) << count;
            }
        }
    }
}

// Steps 7-8 as grid_bvh_build.cu runs them, every launch in a shuffled
// thread order: the oversized-leaf check; finish_leaves_kernel (one thread
// per leaf, slots at 2 leaf_begin / leaf_begin); emit_sizes_kernel per level
// from the deepest; the root's position, emit_positions_kernel per level
// from the root; emit_copy_kernel. Returns false (nothing emitted) when a
// leaf is too large for one thread, unless `large_leaves_too` finishes those
// with the shared iterative build in growable buffers. `bug` breaks one
// step on purpose (1: sizes from the root level down; 2: a leaf's local tree
// with its root's children swapped, as if its stack popped the right child
// first; 3: positions from the deepest level up).
struct EmulatedEmission {
    bool emitted = false;
    Bvh bvh;
};

EmulatedEmission device_emission(const GridHierarchy& h, const BuildOptions& options, std::mt19937& rng,
                                 bool large_leaves_too = false, int bug = 0) {
    EmulatedEmission result;
    const uint32_t n = uint32_t(h.refs.size()), leaf_count = uint32_t(h.leaves.size());
    const uint32_t nodes = h.level_offset.back();
    bool oversized = false;
    for (uint32_t l : shuffled(leaf_count, rng)) oversized |= h.leaf_begin[l + 1] - h.leaf_begin[l] > kDeviceFinishRefs;
    if (oversized && !large_leaves_too) return result;
    const FinishOptions finish{uint32_t(std::max(1, options.max_leaf_size)), options.sah.traversal,
                               options.sah.intersection};
    std::vector<LeafSummary> summaries(leaf_count);
    std::vector<BvhNode> leaf_nodes(2 * size_t{n}, BvhNode{Box3f{}, 0xdeadbeefu, 0xdeadbeefu});
    std::vector<uint32_t> leaf_prims(n, 0xdeadbeefu);
    for (uint32_t l : shuffled(leaf_count, rng)) {
        const uint32_t begin = h.leaf_begin[l], count = h.leaf_begin[l + 1] - begin;
        if (count > kDeviceFinishRefs) {
            std::vector<BvhNode> local_nodes;
            std::vector<uint32_t> local_prims;
            const std::vector<uint32_t> ids(h.leaf_refs.begin() + begin, h.leaf_refs.begin() + begin + count);
            summaries[l] = finish_any_leaf(h.refs, ids, h.leaves[l].depth, finish, local_nodes, local_prims);
            std::copy_n(local_nodes.begin(), summaries[l].node_count, leaf_nodes.begin() + 2 * size_t{begin});
            std::copy_n(local_prims.begin(), summaries[l].prim_count, leaf_prims.begin() + begin);
            continue;
        }
        summaries[l] = gridbvh::finish_small_leaf(h.refs.data(), h.leaf_refs.data() + begin, count, h.leaves[l].depth, finish,
                                                  leaf_nodes.data() + 2 * size_t{begin}, leaf_prims.data() + begin);
        if (bug == 2 && summaries[l].node_count > 1) {
            // The root's children swapped, as if the stack popped the right one first.
            BvhNode* local = leaf_nodes.data() + 2 * size_t{begin};
            std::swap(local[local[0].first], local[local[0].first + 1]);
        }
    }
    std::vector<gridbvh::SubtreeSize> sizes(nodes, gridbvh::SubtreeSize{0xdeadbeefu, 0xdeadbeefu});
    std::vector<Box3f> boxes(nodes);
    std::vector<gridbvh::EmitPosition> at(nodes, gridbvh::EmitPosition{0xdeadbeefu, 0xdeadbeefu, 0xdeadbeefu});
    const size_t levels = h.level_offset.size() - 1;
    for (size_t k = 0; k < levels; ++k) {
        const size_t l = bug == 1 ? k : levels - 1 - k;
        const uint32_t first = h.level_offset[l], end = h.level_offset[l + 1];
        for (uint32_t i : shuffled(end - first, rng)) {
            gridbvh::emit_size_and_box(first + i, h.hnodes.data(), summaries.data(), sizes.data(), boxes.data());
        }
    }
    at[0] = gridbvh::root_position();
    for (size_t k = 0; k < levels; ++k) {
        const size_t l = bug == 3 ? levels - 1 - k : k;
        const uint32_t first = h.level_offset[l], end = h.level_offset[l + 1];
        for (uint32_t i : shuffled(end - first, rng)) gridbvh::emit_positions(first + i, h.hnodes.data(), sizes.data(), at.data());
    }
    if (sizes[0].nodes > 4 * size_t{n} || sizes[0].prims > size_t{n}) return result;  // garbage (a bug): nothing to copy
    result.bvh.nodes.assign(sizes[0].nodes, BvhNode{Box3f{}, 0xdeadbeefu, 0xdeadbeefu});
    result.bvh.prim_indices.assign(sizes[0].prims, 0xdeadbeefu);
    for (uint32_t hn : shuffled(nodes, rng)) {
        const uint32_t first = h.hnodes[hn];
        if (!(first & gridbvh::kLeafBit)) {
            if (at[hn].pos < result.bvh.nodes.size()) gridbvh::emit_inner_node(boxes[hn], at[hn], result.bvh.nodes.data());
            continue;
        }
        const uint32_t leaf = first & ~gridbvh::kLeafBit, begin = h.leaf_begin[leaf];
        const LeafSummary& s = summaries[leaf];
        if (at[hn].pos >= result.bvh.nodes.size() || size_t{at[hn].desc} + s.node_count > result.bvh.nodes.size() + 1 ||
            size_t{at[hn].prim_base} + s.prim_count > result.bvh.prim_indices.size()) {
            continue;  // out of range (a bug)
        }
        gridbvh::emit_leaf(s, leaf_nodes.data() + 2 * size_t{begin}, leaf_prims.data() + begin, at[hn],
                           result.bvh.nodes.data(), result.bvh.prim_indices.data());
    }
    result.emitted = true;
    return result;
}

// The device schedule up to the leaf groups (steps 1-6).
GridHierarchy device_groups(std::span<const Triangle> tris, const BuildOptions& options, bool split, std::mt19937& rng) {
    DeviceRefs dev = device_references(tris, split, options.grid_bvh.split_budget, rng);
    const DeviceGrid g = device_grid(dev, rng);
    GridHierarchy h = device_hierarchy(std::move(dev), g, uint32_t(std::max(1, options.max_leaf_size)), rng);
    group_by_leaf(h, rng);
    return h;
}

// Thousands of small distinct triangles in one Grid0 cell (two far corners
// stretch the scene box): one leaf too large for a device thread, and for
// the CPU's serial recursion (its halves are built in parallel).
SceneGeometry make_crowded_cell(int count, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 0.02f);
    SceneGeometry g;
    test::append(g, {Vec3f(-1000.0f), Vec3f(-1000.0f), Vec3f(-1000.0f)});
    test::append(g, {Vec3f(1000.0f), Vec3f(1000.0f), Vec3f(1000.0f)});
    for (int i = 0; i < count; ++i) {
        const Vec3f a(u(rng), u(rng), u(rng));
        test::append(g, {a, a + Vec3f(0.001f, 0.0f, 0.0f), a + Vec3f(0.0f, 0.001f, 0.0f)});
    }
    return g;
}

TEST(GridBvhDeviceLogic, DeviceEmissionGivesTheCpuBvh) {
    std::mt19937 rng(23);
    std::vector<GoldenScene> scenes = golden_scenes();
    SceneGeometry point;  // 200 references in one Grid0 cell: over the device's cap
    for (int i = 0; i < 200; ++i) test::append(point, {Vec3f(3.0f), Vec3f(3.0f), Vec3f(3.0f)});
    scenes.push_back({"crowded point", std::move(point)});
    size_t emitted = 0, fell_back = 0;
    for (const GoldenScene& scene : scenes) {
        for (const bool split : {false, true}) {
            for (const int leaf : {1, 4, 8}) {
                const BuildOptions options{.max_leaf_size = leaf,
                                           .sah = {.traversal = leaf == 8 ? 2.0f : 1.0f},
                                           .grid_bvh = {.split_budget = 0.5f}};
                const std::string what = scene.name + (split ? " split" : "") + " leaf " + std::to_string(leaf);
                const Bvh cpu = cpu_build(scene.geometry.triangles, options, split);
                const GridHierarchy h = device_groups(scene.geometry.triangles, options, split, rng);
                const EmulatedEmission dev = device_emission(h, options, rng);
                if (!dev.emitted) {
                    ++fell_back;
                    EXPECT_EQ(scene.name, "crowded point") << what << ": only the crowded cell falls back";
                    EXPECT_TRUE(same_bvh(cpu, device_emission(h, options, rng, true).bvh)) << what;
                    continue;
                }
                ++emitted;
                EXPECT_TRUE(same_bvh(cpu, dev.bvh)) << what;
            }
        }
    }
    EXPECT_EQ(fell_back, 6u);
    EXPECT_EQ(emitted, 6u * (scenes.size() - 1));  // "one point" (50 references in one cell) fits
}

TEST(GridBvhDeviceLogic, CrowdedCellFallsBackAndTheSharedBuildStillEqualsCpu) {
    std::mt19937 rng(24);
    // 200 identical triangles: one Grid0 cell over the device's cap.
    SceneGeometry same;
    for (int i = 0; i < 200; ++i) test::append(same, {Vec3f(1, 0, 0), Vec3f(0, 1, 0), Vec3f(0, 0, 1)});
    const BuildOptions options{};
    GridHierarchy h = device_groups(same.triangles, options, false, rng);
    EXPECT_FALSE(device_emission(h, options, rng).emitted);
    EXPECT_TRUE(same_bvh(cpu_build(same.triangles, options, false), device_emission(h, options, rng, true).bvh));
    // The host fallback (what the device build then runs) gives the CPU's BVH.
    EXPECT_TRUE(same_bvh(cpu_build(same.triangles, options, false),
                         emit_grid_bvh_hierarchy(same.triangles, bvh_build_config(options), false, std::move(h))));
    // A leaf of 6,000 distinct references: built by the CPU in parallel halves.
    const SceneGeometry crowded = make_crowded_cell(6000, 25);
    for (const bool split : {false, true}) {
        GridBvhStages stages;
        const Bvh cpu = cpu_build(crowded.triangles, options, split, &stages);
        EXPECT_GT(stages.large_leaves, 0u);
        const GridHierarchy hc = device_groups(crowded.triangles, options, split, rng);
        uint32_t largest = 0;
        for (size_t l = 0; l + 1 < hc.leaf_begin.size(); ++l) largest = std::max(largest, hc.leaf_begin[l + 1] - hc.leaf_begin[l]);
        EXPECT_GT(largest, 4096u);
        EXPECT_FALSE(device_emission(hc, options, rng).emitted);
        EXPECT_TRUE(same_bvh(cpu, device_emission(hc, options, rng, true).bvh)) << split;
    }
}

TEST(GridBvhDeviceLogic, BrokenEmissionStepsAreCaught) {
    std::mt19937 rng(26);
    const SceneGeometry soup = test::make_triangle_soup(3000, 27, Box3f{Vec3f(-5.0f), Vec3f(5.0f)}, 0.3f);
    const BuildOptions options{.max_leaf_size = 8, .grid_bvh = {.split_budget = 0.5f}};
    for (const bool split : {false, true}) {
        const Bvh cpu = cpu_build(soup.triangles, options, split);
        const GridHierarchy h = device_groups(soup.triangles, options, split, rng);
        EXPECT_TRUE(same_bvh(cpu, device_emission(h, options, rng).bvh));
        for (const int bug : {1, 2, 3}) {
            const EmulatedEmission broken = device_emission(h, options, rng, false, bug);
            EXPECT_FALSE(broken.emitted && same_bvh(cpu, broken.bvh)) << "bug " << bug << (split ? " split" : "");
        }
    }
}

}  // namespace
}  // namespace rf
