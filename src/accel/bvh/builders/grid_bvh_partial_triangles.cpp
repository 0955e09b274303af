// Partial triangles for GridBvhSplit (Garanzha 2014, dissertation §4.4).
//
// triangleMaxWidth = sceneExt / 128 (formula 4.1, sceneExt = the longest
// extent of the scene box). Each reference asks for
// reqSplits = floor(longest extent / triangleMaxWidth) splits; when the asks
// exceed the free slots, each gets floor(reqSplits * free / total asks). The
// dissertation gives the proportional formula without a rounding rule or cap
// (§8); rounding down never exceeds the budget, never gives more than was
// asked, and puts the budget on the longest references (a reference asking
// for fewer splits than total / free gets none). Handing out the rounding
// remainders too (one split each to many barely-too-long references) was
// tried; on Sponza it gained far less SAH than this. A reference with s
// splits becomes s + 1 parts along its longest axis, the split planes being
// the Grid0 planes nearest to equal parts; each part's box is the box of the
// triangle clipped (as a polygon) to the part's region. Pass 1 works on the
// triangles with the whole budget, pass 2 on pass 1's output with what is
// left (it splits wide parts along their now-longest axis). Variable output
// counts go through prefix sums, as on the GPU. The per-reference steps
// (request, share, parts, clipping) are grid_bvh_steps.h's, shared with the
// CUDA builder (backend/cuda/grid_bvh_build.cu).
#include "accel/bvh/builders/grid_bvh_partial_triangles.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf::gridbvh {
namespace {

constexpr uint32_t kInvalid = kInvalidRef;
constexpr size_t kChunk = 16 * 1024;

// Exclusive prefix sums in place over fixed chunks (the same for every
// thread count); returns the total.
uint64_t exclusive_scan(std::vector<uint64_t>& values) {
    const size_t n = values.size();
    const size_t chunks = (n + kChunk - 1) / kChunk;
    std::vector<uint64_t> chunk_sum(chunks, 0);
    parallel::for_each_index(size_t{0}, chunks, [&](size_t c) {
        uint64_t sum = 0;
        for (size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) sum += values[i];
        chunk_sum[c] = sum;
    });
    uint64_t running = 0;
    for (uint64_t& s : chunk_sum) {
        const uint64_t c = s;
        s = running;
        running += c;
    }
    parallel::for_each_index(size_t{0}, chunks, [&](size_t c) {
        uint64_t sum = chunk_sum[c];
        for (size_t i = c * kChunk; i < std::min(n, (c + 1) * kChunk); ++i) {
            const uint64_t v = values[i];
            values[i] = sum;
            sum += v;
        }
    });
    return running;
}

// Drops references marked invalid, keeping the order.
std::vector<GridRef> compact(const std::vector<GridRef>& refs) {
    std::vector<uint64_t> offsets(refs.size());
    parallel::for_range(size_t{0}, refs.size(), kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) offsets[i] = refs[i].prim != kInvalid ? 1 : 0;
    });
    const uint64_t total = exclusive_scan(offsets);
    std::vector<GridRef> out;
    budgeted_resize(out, total, "GridBvhSplit: partial triangles");
    parallel::for_range(size_t{0}, refs.size(), kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            if (refs[i].prim != kInvalid) out[offsets[i]] = refs[i];
        }
    });
    return out;
}

// One splitting pass with `available` free reference slots.
std::vector<GridRef> split_pass(std::span<const Triangle> triangles, std::vector<GridRef> refs,
                                const GridFrame& frame, float max_width, uint64_t available) {
    const size_t n = refs.size();
    std::vector<uint64_t> requests(n);
    parallel::for_range(size_t{0}, n, kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) requests[i] = split_request(refs[i], max_width);
    });
    // requests -> prefix C_i of the asks; splits_i = share of the free slots.
    std::vector<uint64_t> splits = requests;
    const uint64_t asked = exclusive_scan(splits);  // splits[i] = C_i for now
    if (asked == 0 || available == 0) return refs;
    parallel::for_range(size_t{0}, n, kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) splits[i] = split_share(uint32_t(requests[i]), asked, available);
    });
    std::vector<uint64_t> slots(n);
    parallel::for_range(size_t{0}, n, kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) slots[i] = splits[i] + 1;
    });
    const uint64_t total = exclusive_scan(slots);
    std::vector<GridRef> parts;
    budgeted_resize(parts, total, "GridBvhSplit: partial triangles");
    parallel::for_range(size_t{0}, n, size_t{1024}, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            GridRef* out = &parts[slots[i]];
            if (splits[i] == 0) {
                *out = refs[i];
            } else {
                write_parts(triangles[refs[i].prim], refs[i], uint32_t(splits[i]), frame, out);
            }
        }
    });
    return compact(parts);
}

}  // namespace

std::vector<GridRef> make_triangle_refs(std::span<const Triangle> triangles) {
    std::vector<GridRef> refs;
    budgeted_resize(refs, triangles.size(), "GridBvh: references");
    parallel::for_range(size_t{0}, triangles.size(), kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) refs[i] = triangle_ref(triangles[i], uint32_t(i));
    });
    return refs;
}

std::vector<GridRef> split_into_partial_triangles(std::span<const Triangle> triangles, std::vector<GridRef> refs,
                                                  const GridFrame& frame, float budget) {
    const float scene_extent = std::max(frame.extent.x, std::max(frame.extent.y, frame.extent.z));
    const float max_width = scene_extent / 128.0f;  // sceneDividePortion = 1/128
    if (!(max_width > 0.0f) || !(budget > 0.0f)) return refs;
    const uint64_t budget_slots = uint64_t(std::floor(double(budget) * double(triangles.size())));
    const size_t original = refs.size();
    refs = split_pass(triangles, std::move(refs), frame, max_width, budget_slots);
    const uint64_t used = refs.size() - original;
    if (used < budget_slots) refs = split_pass(triangles, std::move(refs), frame, max_width, budget_slots - used);
    return refs;
}

}  // namespace rf::gridbvh
