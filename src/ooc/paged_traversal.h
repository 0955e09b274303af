// Ray queries on a paged scene (Garanzha 2014, §6.3.3, Fig. 6.4), one
// iteration of one ray, written once for both backends. The query loop
// around it (paged_accel.cpp on the CPU) runs iterations over all pending
// rays, then lets the geometry page manager load what they asked for,
// until no ray asks for anything.
//
// In an iteration a ray walks the top grid with a 3D-DDA from its restart
// cell, never past its nearest hit so far; in each cell it walks the cell's
// middle BVH, and for every page whose clipped box it meets:
//   - WasRead (searched by every ray in an earlier iteration): skipped;
//   - cached: its use is marked, the ray goes into the page's quantised
//     space (t is unchanged by the affine map) and through its bottom BVH;
//   - missing: the first such page of this iteration is requested and its
//     cell becomes the restart cell; later missing pages wait. The walk
//     goes on, testing every cached page further along (speculative
//     testing: a hit there shortens the ray, so farther pages may never be
//     needed).
// Any-hit rays (shadows) stop at their first hit among cached pages, and
// request their first missing page only when the iteration ends without
// one (the seed's §6.3.3 rule: every cached page is tested before a
// missing one is asked for, so a shadow ray blocked by cached geometry
// loads nothing).
// A ray is finished when an iteration requested nothing.
//
// Robustness: the grid's cells hold every page within a small margin of
// them (top_grid.cpp); plane distances are recomputed from the planes, as
// in trace/grid_traversal.h; box tests are the BVH's (Ize 2013).
#pragma once

#include <cstdint>
#include <cstring>

#include "core/assert.h"
#include "core/rounded_arithmetic.h"
#include "ooc/pack_format.h"
#include "ooc/page_table.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "trace/bvh_traversal.h"
#include "trace/triangle_intersect.h"

namespace rf::pack {

// The resident levels and the geometry pages as the per-ray code sees them.
struct PagedSceneView {
    const PageInfo* pages = nullptr;
    const uint32_t* cell_roots = nullptr;
    const BvhNode* middle_nodes = nullptr;
    PageTableView geometry;
    Box3f grid_bounds;
    Vec3f cell_size;
    int res[3] = {1, 1, 1};
    uint32_t page_count = 0;
};

inline constexpr uint32_t kRayFinished = 0xFFFFFFFFu;
inline constexpr uint32_t kRayNotStarted = 0xFFFFFFFEu;

// What a ray keeps between iterations (Garanzha 2014's restart record).
struct PagedRayState {
    Hit hit;                          // nearest so far; hit.t starts at ray.tmax
    uint32_t restart = kRayNotStarted; // cell to resume in, or kRayNotStarted / kRayFinished
    uint32_t occluded = 0;            // any-hit queries: found something
};

struct PagedCounters {
    uint32_t cells = 0;       // top-grid cells visited
    uint32_t middle = 0;      // middle-BVH nodes visited
    uint32_t pages = 0;       // cached pages searched
    uint32_t nodes = 0;       // bottom-BVH nodes visited
    uint32_t quads = 0;       // quads tested
};

namespace detail {

// The last pages a ray searched in this iteration: a page spanning several
// cells is searched once.
struct PageMailbox {
    static constexpr int kSize = 4;
    uint32_t ids[kSize] = {kInvalidId, kInvalidId, kInvalidId, kInvalidId};
    int next = 0;
    RF_HDI bool seen(uint32_t page) const {
        for (int i = 0; i < kSize; ++i)
            if (ids[i] == page) return true;
        return false;
    }
    RF_HDI void add(uint32_t page) {
        ids[next] = page;
        next = (next + 1) & (kSize - 1);
    }
};

RF_HDI Triangle quad_half(const Quad& q, int half) {
    const int c = half == 0 ? 1 : 2, d = half == 0 ? 2 : 3;
    return {Vec3f(float(q.v[0][0]), float(q.v[0][1]), float(q.v[0][2])),
            Vec3f(float(q.v[c][0]), float(q.v[c][1]), float(q.v[c][2])),
            Vec3f(float(q.v[d][0]), float(q.v[d][1]), float(q.v[d][2]))};
}

// A node's box in the page's quantised space, grown by `pad` units: the ray
// is taken into that space with rounding, the triangles are tested in world
// space (test_quads), so a box must never cull what the world test hits.
RF_HDI Box3f page_box(const PageNode& n, float pad) {
    return {Vec3f(float(n.lo[0]) - pad, float(n.lo[1]) - pad, float(n.lo[2]) - pad),
            Vec3f(float(n.hi[0]) + pad, float(n.hi[1]) + pad, float(n.hi[2]) + pad)};
}

// Half `half` of quad `q` decoded to world space. On a writer's lattice
// (page_builder.h) offset + scale * q is exact, so a vertex two pages share
// is the same point in both, and the watertight test in world space leaves
// no gap at their seam.
RF_HDI Triangle decoded_quad_half(const Quad& q, int half, const PageInfo& info) {
    const Triangle t = quad_half(q, half);
    return {info.offset + info.scale * t.v0, info.offset + info.scale * t.v1, info.offset + info.scale * t.v2};
}

// A node to come back to and where the ray enters it (skipped once a hit is closer).
struct PendingNode {
    uint32_t node;
    float entry;
};

// Tests quads [first, first + count) of a page, decoded to world space,
// against the world ray; true when `hit` got closer.
template <bool kAnyHit>
RF_HDI bool test_quads(const Quad* quads, uint32_t first, uint32_t count, uint32_t page, const PageInfo& info,
                       const WatertightRay& wt, float tmin, Hit& hit, PagedCounters& counters) {
    bool found = false;
    for (uint32_t q = first; q < first + count; ++q) {
        ++counters.quads;
        for (int half = 0; half < 2; ++half) {
            TriangleHit th;
            if (!intersect_triangle(wt, decoded_quad_half(quads[q], half, info), tmin, hit.t, th)) continue;
            hit.t = th.t;
            hit.u = th.u;
            hit.v = th.v;
            hit.prim = page * kTrianglesPerPageSlot + 2 * q + uint32_t(half);
            found = true;
            if (kAnyHit) return true;
        }
    }
    return found;
}

// Searches one cached page, nearer child first; true when `hit` got closer
// (or, any-hit, when anything was hit).
template <bool kAnyHit>
RF_HDI bool search_page(const uint8_t* bytes, const PageInfo& info, uint32_t page, const Ray& world, Hit& hit,
                        PagedCounters& counters) {
    GeometryPageHeader header;
    memcpy(&header, bytes, sizeof(header));
    const auto* nodes = reinterpret_cast<const PageNode*>(bytes + sizeof(header));
    const auto* quads = reinterpret_cast<const Quad*>(bytes + sizeof(header) + header.node_count * sizeof(PageNode));
    Ray local;
    local.org = (world.org - info.offset) / info.scale;
    local.dir = world.dir / info.scale;
    const rf::detail::SlabRay slab = rf::detail::SlabRay::make(local);
    const WatertightRay wt = WatertightRay::make(world);
    // One quantisation unit, plus the rounding of a far origin's coordinates.
    const float far = fmaxf(fabsf(local.org.x), fmaxf(fabsf(local.org.y), fabsf(local.org.z)));
    const float pad = 1.0f + far * 0x1p-20f;
    bool found = false;
    PendingNode stack[kBvhMaxDepth];
    int top = 0;
    float entry;
    ++counters.nodes;
    if (!rf::detail::slab_test(slab, page_box(nodes[0], pad), world.tmin, hit.t, entry)) return false;
    uint32_t node = 0;
    for (;;) {
        const PageNode& n = nodes[node];
        if (n.is_leaf()) {
            if (test_quads<kAnyHit>(quads, n.first(), n.count(), page, info, wt, world.tmin, hit, counters)) {
                found = true;
                if (kAnyHit) return true;
            }
        } else {
            counters.nodes += 2;
            float e0, e1;
            const bool h0 = rf::detail::slab_test(slab, page_box(nodes[n.left()], pad), world.tmin, hit.t, e0);
            const bool h1 = rf::detail::slab_test(slab, page_box(nodes[n.left() + 1], pad), world.tmin, hit.t, e1);
            if (h0 && h1) {
                const bool first_near = e0 <= e1;
                if (top < kBvhMaxDepth) stack[top++] = {n.left() + (first_near ? 1u : 0u), first_near ? e1 : e0};
                node = n.left() + (first_near ? 0u : 1u);
                continue;
            }
            if (h0 || h1) {
                node = n.left() + (h0 ? 0u : 1u);
                continue;
            }
        }
        // Back to the nearest pending node the ray still reaches before its hit.
        for (;;) {
            if (top == 0) return found;
            const PendingNode p = stack[--top];
            if (p.entry <= hit.t * rf::detail::kSlabFarScale) {
                node = p.node;
                break;
            }
        }
    }
}

// The 3D-DDA over the top grid's cells (per-axis cell sizes).
struct GridWalk {
    int cell[3];
    int step[3];
    float next[3];  // distance to the next boundary plane per axis

    // Rounded products and sums (core/rounded_arithmetic.h): no fused
    // multiply-add on the device, so both backends walk the same cells.
    RF_HDI float plane(const PagedSceneView& v, int axis, int i) const {
        return add_rn(v.grid_bounds.lo[axis], mul_rn(float(i), v.cell_size[axis]));
    }
    RF_HDI void init(const PagedSceneView& v, const Ray& ray, const int start[3]) {
        for (int a = 0; a < 3; ++a) {
            cell[a] = start[a];
            step[a] = ray.dir[a] > 0.0f ? 1 : (ray.dir[a] < 0.0f ? -1 : 0);
            next[a] = step[a] == 0 ? kInfinity : (plane(v, a, cell[a] + (step[a] > 0)) - ray.org[a]) / ray.dir[a];
        }
    }
    RF_HDI float exit() const { return fminf(next[0], fminf(next[1], next[2])); }
    // Steps into the next cell; false when the ray leaves the grid.
    RF_HDI bool advance(const PagedSceneView& v, const Ray& ray) {
        const int a = (next[0] <= next[1] && next[0] <= next[2]) ? 0 : (next[1] <= next[2] ? 1 : 2);
        cell[a] += step[a];
        if (cell[a] < 0 || cell[a] >= v.res[a]) return false;
        next[a] = (plane(v, a, cell[a] + (step[a] > 0)) - ray.org[a]) / ray.dir[a];
        return true;
    }
    [[nodiscard]] RF_HDI uint32_t index(const PagedSceneView& v) const {
        return uint32_t((cell[2] * v.res[1] + cell[1]) * v.res[0] + cell[0]);
    }
};

// The first cell of a fresh ray; false when it misses the grid.
RF_HDI bool start_cell(const PagedSceneView& v, const Ray& ray, float tmax, int out[3]) {
    const rf::detail::SlabRay slab = rf::detail::SlabRay::make(ray);
    float entry;
    if (!rf::detail::slab_test(slab, v.grid_bounds, ray.tmin, tmax, entry)) return false;
    for (int a = 0; a < 3; ++a) {
        const float p = add_rn(ray.org[a], mul_rn(ray.dir[a], entry));
        // Clamped as a float (NaN goes to 0): the conversion to int is then defined.
        const float c = floorf((p - v.grid_bounds.lo[a]) / v.cell_size[a]);
        out[a] = c >= 0.0f ? (c < float(v.res[a] - 1) ? int(c) : v.res[a] - 1) : 0;
    }
    return true;
}

// One ray's visit of a cell's middle BVH, nearer child first: cached pages
// are searched, the first missing one is requested (see the file's comment).
struct CellVisit {
    const PagedSceneView& v;
    const Ray& ray;
    const rf::detail::SlabRay& slab;
    PagedRayState& state;
    PagedCounters& counters;
    PageMailbox mailbox;
    bool requested = false;        // a missing page is (closest hit) or will be (any hit) requested
    uint32_t deferred_page = 0;    // any hit: the page to request if no cached page blocks the ray

    // True when an any-hit query found a hit (the ray is then finished).
    template <bool kAnyHit>
    RF_HDI bool walk(uint32_t root, uint32_t cell) {
        PendingNode stack[kBvhMaxDepth];
        int top = 0;
        float entry;
        ++counters.middle;
        if (!rf::detail::slab_test(slab, v.middle_nodes[root].bounds, ray.tmin, state.hit.t, entry)) return false;
        uint32_t node = root;
        for (;;) {
            const BvhNode& n = v.middle_nodes[node];
            if (n.is_leaf()) {
                if (visit_page<kAnyHit>(n.first, cell)) return true;
            } else {
                counters.middle += 2;
                float e0, e1;
                const bool h0 = rf::detail::slab_test(slab, v.middle_nodes[n.first].bounds, ray.tmin, state.hit.t, e0);
                const bool h1 = rf::detail::slab_test(slab, v.middle_nodes[n.first + 1].bounds, ray.tmin, state.hit.t, e1);
                if (h0 && h1) {
                    const bool first_near = e0 <= e1;
                    if (top < kBvhMaxDepth) stack[top++] = {n.first + (first_near ? 1u : 0u), first_near ? e1 : e0};
                    node = n.first + (first_near ? 0u : 1u);
                    continue;
                }
                if (h0 || h1) {
                    node = n.first + (h0 ? 0u : 1u);
                    continue;
                }
            }
            for (;;) {
                if (top == 0) return false;
                const PendingNode p = stack[--top];
                if (p.entry <= state.hit.t * rf::detail::kSlabFarScale) {
                    node = p.node;
                    break;
                }
            }
        }
    }

    template <bool kAnyHit>
    RF_HDI bool visit_page(uint32_t page, uint32_t cell) {
        const uint32_t d = v.geometry.descriptor(page);
        if ((d & kWasRead) || mailbox.seen(page)) return false;
        if (d & kOutOfCore) {
            if (!requested) {
                if (kAnyHit) deferred_page = page;
                else v.geometry.request(page);
                requested = true;
                state.restart = cell;
            }
            return false;
        }
        v.geometry.request(page);  // a use, for the LFU counts
        mailbox.add(page);
        ++counters.pages;
        const uint8_t* bytes = v.geometry.slots + uint64_t(d & kSlotMask) * v.geometry.slot_bytes;
        if (search_page<kAnyHit>(bytes, v.pages[page], page, ray, state.hit, counters) && kAnyHit) {
            state.occluded = 1;
            state.restart = kRayFinished;
            return true;
        }
        return false;
    }
};

}  // namespace detail

// One iteration of one ray (see above). Returns true when the ray asked for
// a page and must run again after the page manager's swap.
template <bool kAnyHit>
RF_HD bool paged_iteration(const PagedSceneView& v, const Ray& ray, PagedRayState& state, PagedCounters& counters) {
    using namespace detail;
    if (state.restart == kRayFinished) return false;
    int start[3];
    if (state.restart == kRayNotStarted) {
        // A ray with a non-finite origin or direction meets nothing (and an
        // infinite tmax is the largest float), so the walk below always ends.
        const bool finite = fabsf(ray.org.x) <= kInfinity && fabsf(ray.org.y) <= kInfinity &&
                            fabsf(ray.org.z) <= kInfinity && fabsf(ray.dir.x) <= kInfinity &&
                            fabsf(ray.dir.y) <= kInfinity && fabsf(ray.dir.z) <= kInfinity;
        state.hit.t = fminf(ray.tmax, kInfinity);
        if (v.page_count == 0 || !finite || !start_cell(v, ray, state.hit.t, start)) {
            state.restart = kRayFinished;
            return false;
        }
    } else {
        const uint32_t c = state.restart;
        start[0] = int(c % uint32_t(v.res[0]));
        start[1] = int((c / uint32_t(v.res[0])) % uint32_t(v.res[1]));
        start[2] = int(c / (uint32_t(v.res[0]) * uint32_t(v.res[1])));
    }
    GridWalk walk;
    walk.init(v, ray, start);
    const rf::detail::SlabRay slab = rf::detail::SlabRay::make(ray);
    CellVisit visit{v, ray, slab, state, counters, PageMailbox{}, false, 0};
    // A straight line crosses at most res[0] + res[1] + res[2] cells; the cap
    // also ends walks whose plane distances rounding made non-finite.
    for (int steps = v.res[0] + v.res[1] + v.res[2] + 2; steps > 0; --steps) {
        ++counters.cells;
        const uint32_t root = v.cell_roots[walk.index(v)];
        if (root != kEmptyCell && visit.walk<kAnyHit>(root, walk.index(v))) return false;
        // A hit before this cell's far side cannot be beaten further on.
        if (state.hit.t <= walk.exit()) break;
        if (!walk.advance(v, ray)) break;
    }
    const bool requested = visit.requested;
    if (!requested) state.restart = kRayFinished;
    else if (kAnyHit) v.geometry.request(visit.deferred_page);  // no cached page blocked the ray
    return requested;
}

}  // namespace rf::pack
