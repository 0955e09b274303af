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
// counts go through prefix sums, as on the GPU.
#include "accel/bvh/build/grid_bvh_partial_triangles.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>

#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf::gridbvh {
namespace {

constexpr uint32_t kInvalid = 0xffffffffu;
constexpr size_t kChunk = 16 * 1024;
constexpr uint32_t kMaxSplitsPerRef = 4096;  // far above 128 parts: only bounds the arithmetic

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

// std::min/max compile to single instructions (rf::min/max call fminf/fmaxf).
inline Vec3f vmin(const Vec3f& a, const Vec3f& b) {
    return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3f vmax(const Vec3f& a, const Vec3f& b) {
    return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}

Box3f intersect(const Box3f& a, const Box3f& b) {
    return {vmax(a.lo, b.lo), vmin(a.hi, b.hi)};
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

// Writes the s + 1 parts of `ref` (triangle `tri`) into out[0 .. s]; slots
// of parts that came out empty are marked invalid. At least one part is kept.
void write_parts(const Triangle& tri, const GridRef& ref, uint32_t splits, const GridFrame& frame, GridRef* out) {
    const Box3f box = ref.bounds();
    const int axis = box.largest_axis();
    const float lo = box.lo[axis], hi = box.hi[axis];
    float previous = lo;
    bool any = false;
    for (uint32_t k = 0; k <= splits; ++k) {
        float next = hi;
        if (k < splits) {
            // The Grid0 plane nearest to the k+1-th equal division.
            const double x = double(lo) + double(hi - lo) * double(k + 1) / double(splits + 1);
            const double g = std::round((x - double(frame.origin[axis])) * double(frame.to_cell[axis]));
            next = frame.plane(int(std::clamp(g, 0.0, double(kFineRes))), axis);
            if (!(next > previous && next < hi)) {  // collapsed onto a neighbour: fewer parts
                out[k].prim = kInvalid;
                continue;
            }
        }
        Box3f region = box;
        region.lo[axis] = previous;
        region.hi[axis] = next;
        previous = next;
        const Box3f part = clip_triangle_to_box(tri, region);
        if (part.is_empty()) {
            out[k].prim = kInvalid;
            continue;
        }
        out[k] = GridRef{part.lo, ref.prim, part.hi, 0};
        any = true;
    }
    if (!any) out[0] = ref;
}

// One splitting pass with `available` free reference slots.
std::vector<GridRef> split_pass(std::span<const Triangle> triangles, std::vector<GridRef> refs,
                                const GridFrame& frame, float max_width, uint64_t available) {
    const size_t n = refs.size();
    std::vector<uint64_t> requests(n);
    parallel::for_range(size_t{0}, n, kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const Vec3f e = refs[i].bounds().extent();
            const float widest = std::max(e.x, std::max(e.y, e.z));
            const float req = std::floor(widest / max_width);
            requests[i] = req >= 1.0f ? uint64_t(std::min(req, float(kMaxSplitsPerRef))) : 0;
        }
    });
    // requests -> prefix C_i of the asks; splits_i = share of the free slots.
    std::vector<uint64_t> splits = requests;
    const uint64_t asked = exclusive_scan(splits);  // splits[i] = C_i for now
    if (asked == 0 || available == 0) return refs;
    parallel::for_range(size_t{0}, n, kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            if (asked <= available) {
                splits[i] = requests[i];
            } else {
                using u128 = unsigned __int128;
                splits[i] = uint64_t(u128(requests[i]) * available / asked);
            }
        }
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

Box3f clip_triangle_to_box(const Triangle& tri, const Box3f& region) {
    // Sutherland-Hodgman: each plane adds at most one vertex (3 + 6 = 9).
    Vec3f poly[12] = {tri.v0, tri.v1, tri.v2};
    Vec3f next[12];
    int count = 3;
    for (int axis = 0; axis < 3 && count > 0; ++axis) {
        for (int side = 0; side < 2 && count > 0; ++side) {
            const float plane = side == 0 ? region.lo[axis] : region.hi[axis];
            auto inside = [&](const Vec3f& p) { return side == 0 ? p[axis] >= plane : p[axis] <= plane; };
            int out = 0;
            for (int i = 0; i < count; ++i) {
                const Vec3f& a = poly[i];
                const Vec3f& b = poly[(i + 1) % count];
                const bool in_a = inside(a), in_b = inside(b);
                if (in_a) next[out++] = a;
                if (in_a != in_b) {
                    const float t = (plane - a[axis]) / (b[axis] - a[axis]);
                    Vec3f v = a + (b - a) * t;
                    v[axis] = plane;  // exactly on the plane, so parts meet without gaps
                    next[out++] = v;
                }
            }
            count = out;
            std::copy(next, next + count, poly);
        }
    }
    Box3f box;
    if (count == 0) return box;
    for (int i = 0; i < count; ++i) box = {vmin(box.lo, poly[i]), vmax(box.hi, poly[i])};
    // Interpolated coordinates may be a few ulps inside the true part; grow
    // slightly so the parts still cover the whole triangle, then clamp.
    for (int axis = 0; axis < 3; ++axis) {
        const float scale = std::max(std::fabs(box.lo[axis]), std::fabs(box.hi[axis]));
        const float eps = 8.0f * FLT_EPSILON * scale;
        box.lo[axis] -= eps;
        box.hi[axis] += eps;
    }
    const Box3f tri_box{vmin(tri.v0, vmin(tri.v1, tri.v2)), vmax(tri.v0, vmax(tri.v1, tri.v2))};
    box = intersect(intersect(box, region), tri_box);
    return box;
}

std::vector<GridRef> make_triangle_refs(std::span<const Triangle> triangles) {
    std::vector<GridRef> refs;
    budgeted_resize(refs, triangles.size(), "GridBvh: references");
    parallel::for_range(size_t{0}, triangles.size(), kChunk, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const Triangle& t = triangles[i];
            const Vec3f tlo = vmin(t.v0, vmin(t.v1, t.v2)), thi = vmax(t.v0, vmax(t.v1, t.v2));
            refs[i] = GridRef{tlo, uint32_t(i), thi, 0};
        }
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
