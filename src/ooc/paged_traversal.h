// Ray queries on a paged scene (Garanzha 2014, §6.3.3, Fig. 6.4), one
// iteration of one ray, written once for both backends. The query loop
// around it (paged_accel.cpp on the CPU) runs iterations over all pending
// rays, then lets the geometry page manager load what they asked for,
// until no ray asks for anything.
//
// In an iteration a ray walks the top level, never past its nearest hit so
// far: the top BVH from its root (TopLevel::WideBvh), or the top grid with a
// 3D-DDA from its restart cell and in each cell the cell's middle BVH
// (TopLevel::Grid). For every page whose box it meets:
//   - WasRead (searched by every ray in an earlier iteration): skipped;
//   - cached: its use is marked, the ray goes into the page's quantised
//     space (t is unchanged by the affine map) and through the page's wide
//     BVH, its triangles tested in world space;
//   - missing: the first such page of this iteration is requested (with the
//     grid its cell becomes the restart cell); later missing pages wait. The walk
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
// Robustness: wide nodes are tested with boxes grown by a pad that covers
// the rounding (WideBoxRay); the grid's cells hold every page within a
// small margin of them (top_grid.cpp); plane distances are recomputed from
// the planes, as in trace/grid_traversal.h; the middle BVHs' box tests are
// the binary BVH's (Ize 2013).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

#include "core/assert.h"
#include "core/rounded_arithmetic.h"
#include "ooc/pack_format.h"
#include "ooc/page_table.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/core/float_bits.h"
#include "rayforge/core/host_device.h"
#include "rayforge/math/ray.h"
#include "trace/bvh_traversal.h"
#include "trace/triangle_intersect.h"

// The host traverses pages with SIMD; CUDA sources (both passes) take the
// scalar form.
#if !defined(__CUDACC__)
#define RF_PAGED_SIMD 1
#include "backend/cpu/wide_bvh_traversal.h"
#include "core/simd.h"
#endif

namespace rf::pack {

// The resident levels and the geometry pages as the per-ray code sees them.
struct PagedSceneView {
    const PageInfo* pages = nullptr;
    const PageNode* page_roots = nullptr;    // a copy of every page's root node (resident)
    const TopRef* refs = nullptr;            // what the top level reaches
    const InstanceInfo* instances = nullptr;
    // TopLevel::WideBvh (top_nodes set): the top BVH (leaf item k is refs[k]) ...
    const PageNode* top_nodes = nullptr;
    float coord_scale = 1.0f;  // largest |coordinate| of the scene's bounds
    // ... or TopLevel::Grid: the grid and the cells' middle BVHs (leaves: a reference).
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

inline constexpr uint32_t kNotWaiting = 0xFFFFFFFFu;

// What a ray keeps between iterations (Garanzha 2014's restart record).
struct PagedRayState {
    Hit hit;                          // nearest so far; hit.t starts at ray.tmax
    uint32_t restart = kRayNotStarted; // cell to resume in, or kRayNotStarted / kRayFinished
    uint32_t occluded = 0;            // any-hit queries: found something
    uint32_t waiting_for = kNotWaiting;  // the page its last run asked for
    uint32_t instance = kNoInstance;     // the instance of the hit's page (kNoInstance: a world-space page)
};

// The pages the last swap loaded (`count` of them at `pages`), or
// kEveryPageFresh: more than kMaxFreshPages, or the loop's first iteration.
// A ray waiting for a page runs again only when that page or one of these
// lies on its way (paged_iteration).
inline constexpr uint32_t kMaxFreshPages = 16;
inline constexpr uint32_t kEveryPageFresh = 0xFFFFFFFFu;
struct FreshPages {
    const uint32_t* pages = nullptr;
    uint32_t count = kEveryPageFresh;
};

struct PagedCounters {
    uint32_t runs = 0;        // iterations the ray ran (not sat out waiting for its page)
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

// ---- The page BVH (CWBVH nodes in the page's quantised space) ----
//
// A reference on the page traversal's stack: an inner node's index, or a
// leaf: kPageLeafRef | first quad << 2 | quad count.
inline constexpr uint32_t kPageLeafRef = 0x80000000u;
// At most seven children wait per wide level.
inline constexpr int kPageStackSize = kCwbvhMaxDepth * (kCwbvhWidth - 1) + 1;

// The reference of slot `s` (nonempty) of `n`.
RF_HDI uint32_t page_child_ref(const PageNode& n, int s) {
    const uint8_t meta = n.meta[s];
    if (cwbvh_meta_is_inner(meta)) return n.base_index_child + cwbvh_popc(n.imask & ((1u << s) - 1u));
    return kPageLeafRef | (n.base_index_triangle + (meta & 31u)) << 2 | cwbvh_popc(meta >> 5);
}

// Per-ray constants of the wide node test in the CWBVH paper's form (Ylitie,
// Karras and Laine 2017, §4.3): the ray is taken into a node's quantised
// frame once per node, so a child plane's distance is one multiply-add,
//   t = q * (step * rcp) + (p - org -/+ pad) * rcp,
// with the entry (near) and exit (far) planes of each axis picked once per
// ray from the direction's signs. The boxes are grown by `pad` on every
// side, which covers the rounding of those few operations (a few ulps of
// the coordinates' magnitude: (coord_scale + |origin|) * 2^-20) plus
// `pad_units` (a page's boxes: 2 quantisation units, as the ray is taken into
// the page's space with rounding while its triangles are tested in world
// space). Direction components too small for a finite reciprocal are
// replaced by a tiny signed value, as wide_bvh_traversal.h's BoxRay does, so
// every distance is finite: no NaN from 0 * inf.
struct WideBoxRay {
    float org[3];
    float rcp[3];
    float near_shift[3], far_shift[3];  // -pad / +pad: the entry and exit planes moved outward
    uint8_t near_q[3], far_q[3];        // byte offsets in a PageNode of each axis's entry / exit q arrays
    float tmin;

    static RF_HDI WideBoxRay make(const Ray& ray, float pad_units, float coord_scale) {
        WideBoxRay r;
        const float ax = fabsf(ray.org.x), ay = fabsf(ray.org.y), az = fabsf(ray.org.z);
        const float far = ax > ay ? (ax > az ? ax : az) : (ay > az ? ay : az);  // not fmaxf: a libm call on the host
        const float magnitude = far > coord_scale ? (far > 0x1p-20f ? far : 0x1p-20f) : (coord_scale > 0x1p-20f ? coord_scale : 0x1p-20f);
        const float pad = pad_units + (coord_scale + far) * 0x1p-20f;
        const float tiny = magnitude * 0x1p-100f;
        for (int a = 0; a < 3; ++a) {
            float d = ray.dir[a];
            if (fabsf(d) < tiny) d = copysignf(tiny, d);
            r.org[a] = ray.org[a];
            r.rcp[a] = 1.0f / d;
            const bool negative = r.rcp[a] < 0.0f;
            const uint8_t lo = uint8_t(offsetof(PageNode, q_lo_x) + 8 * a), hi = uint8_t(offsetof(PageNode, q_hi_x) + 8 * a);
            r.near_q[a] = negative ? hi : lo;
            r.far_q[a] = negative ? lo : hi;
            r.near_shift[a] = negative ? pad : -pad;
            r.far_shift[a] = -r.near_shift[a];
        }
        r.tmin = ray.tmin;
        return r;
    }

    // The same ray in a page's quantised space (world = offset + scale *
    // local), without a division: the writer's scales are powers of two
    // (checked when the file is opened), so 1 / scale and rcp * scale are
    // exact. The world's tiny-component replacement carries over (its
    // reciprocals stay finite), and the pad is the page's.
    RF_HDI WideBoxRay to_page(const Vec3f& offset, const Vec3f& scale, float pad_units, float coord_scale) const {
        WideBoxRay r = *this;
        float far = 0.0f;
        for (int a = 0; a < 3; ++a) {
            r.org[a] = (org[a] - offset[a]) * power_of_two_reciprocal(scale[a]);
            r.rcp[a] = rcp[a] * scale[a];
            const float o = fabsf(r.org[a]);
            far = o > far ? o : far;
        }
        const float pad = pad_units + (coord_scale + far) * 0x1p-20f;
        for (int a = 0; a < 3; ++a) {
            r.near_shift[a] = r.near_shift[a] < 0.0f ? -pad : pad;
            r.far_shift[a] = -r.near_shift[a];
        }
        return r;
    }
    // 1 / x for a power of two x whose reciprocal is a normal float.
    static RF_HDI float power_of_two_reciprocal(float x) {
        return bits_to_float((254u - ((float_to_bits(x) >> 23) & 0xFFu)) << 23);
    }
};
static_assert(offsetof(PageNode, q_lo_y) == offsetof(PageNode, q_lo_x) + 8 &&
              offsetof(PageNode, q_hi_x) == offsetof(PageNode, q_lo_x) + 24);

#if defined(RF_PAGED_SIMD)
// The host's node test: all eight children at once; leaf triangles four at
// a time with the in-core packed watertight test.
struct PageNodeTest {
    WideBoxRay r;

    static RF_SIMD_INLINE PageNodeTest make(const WideBoxRay& r) { return {r}; }
    // Bit s: the ray enters slot s's box before tmax; near[s] where (near: 32-byte aligned).
    RF_SIMD_INLINE unsigned hits(const PageNode& n, float tmax, float* near) const {
        using namespace simd;
        const uint8_t* bytes = reinterpret_cast<const uint8_t*>(&n);
        vfloat<8> t_near = set1<8>(r.tmin), t_far = set1<8>(tmax);
        for (int a = 0; a < 3; ++a) {
            const float rcp = r.rcp[a], to_plane = n.p[a] - r.org[a];
            const vfloat<8> scaled_step = set1<8>(cwbvh_step(n.e[a]) * rcp);
            const vfloat<8> t0 = fmadd(load_bytes<8>(bytes + r.near_q[a]), scaled_step, set1<8>((to_plane + r.near_shift[a]) * rcp));
            const vfloat<8> t1 = fmadd(load_bytes<8>(bytes + r.far_q[a]), scaled_step, set1<8>((to_plane + r.far_shift[a]) * rcp));
            t_near = max(t0, t_near);
            t_far = min(t1, t_far);
        }
        store<8>(near, t_near);
        return bits(cmp_le(t_near, t_far)) & nonzero_bytes8(n.meta);
    }
    // The keys (simd::distance_key) of the slots in `mask`, nearest first.
    RF_SIMD_INLINE void sort(const float* near, unsigned mask, uint32_t* keys) const {
        simd::sort_distance_keys<8>(simd::load<8>(near), mask, keys);
    }
};

struct PageLeafTest {
    wide_detail::PackRay ray;
    static RF_SIMD_INLINE PageLeafTest make(const Ray& world) { return {wide_detail::PackRay::make(world)}; }

    // Quads [first, first + count) decoded to world space, two to a pack;
    // true when `hit` got closer (any hit: when anything was hit).
    template <bool kAnyHit>
    RF_SIMD_INLINE bool test(const Quad* quads, uint32_t first, uint32_t count, uint32_t page, const PageInfo& info,
                             float tmin, Hit& hit) const {
        bool found = false;
        for (uint32_t q0 = first; q0 < first + count; q0 += 2) {
            TrianglePack pack;
            for (int lane = 0; lane < 4; ++lane) {
                const uint32_t q = q0 + uint32_t(lane >> 1);
                const int half = lane & 1;
                const Quad& quad = quads[q < first + count ? q : q0];
                // An unpaired triangle's second half (v3 = v0) has no area: NaN, as in-core packs do.
                const bool empty = q >= first + count ||
                                   (half == 1 && quad.v[3][0] == quad.v[0][0] && quad.v[3][1] == quad.v[0][1] &&
                                    quad.v[3][2] == quad.v[0][2]);
                const int corner[3] = {0, half == 0 ? 1 : 2, half == 0 ? 2 : 3};
                for (int k = 0; k < 3; ++k)
                    for (int a = 0; a < 3; ++a)
                        pack.v[k][a][lane] =
                            empty ? __builtin_nanf("") : info.offset[a] + info.scale[a] * float(quad.v[corner[k]][a]);
            }
            alignas(16) float t[4], u[4], v[4];
            unsigned lanes = wide_detail::intersect_pack(ray, pack, tmin, hit.t, t, u, v);
            if (lanes == 0) continue;
            int best = simd::first_bit(lanes);
            for (lanes &= lanes - 1; lanes; lanes &= lanes - 1) {
                const int lane = simd::first_bit(lanes);
                if (t[lane] < t[best]) best = lane;
            }
            hit.t = t[best];
            hit.u = u[best];
            hit.v = v[best];
            hit.prim = page * kTrianglesPerPageSlot + 2 * (q0 + uint32_t(best >> 1)) + uint32_t(best & 1);
            found = true;
            if (kAnyHit) return true;
        }
        return found;
    }
};
#else
// The device's (and any non-SIMD build's) page tests: the same node test
// one child at a time, one triangle at a time.
struct PageNodeTest {
    WideBoxRay r;

    static RF_HDI PageNodeTest make(const WideBoxRay& r) { return {r}; }
    RF_HDI unsigned hits(const PageNode& n, float tmax, float* near) const {
        const uint8_t* bytes = reinterpret_cast<const uint8_t*>(&n);
        float scaled_step[3], near_base[3], far_base[3];
        for (int a = 0; a < 3; ++a) {
            const float rcp = r.rcp[a], to_plane = n.p[a] - r.org[a];
            scaled_step[a] = cwbvh_step(n.e[a]) * rcp;
            near_base[a] = (to_plane + r.near_shift[a]) * rcp;
            far_base[a] = (to_plane + r.far_shift[a]) * rcp;
        }
        unsigned mask = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            if (n.meta[s] == kCwbvhEmptyMeta) continue;
            float t_near = r.tmin, t_far = tmax;
            for (int a = 0; a < 3; ++a) {
                const float t0 = fmaf(float(bytes[r.near_q[a] + s]), scaled_step[a], near_base[a]);
                const float t1 = fmaf(float(bytes[r.far_q[a] + s]), scaled_step[a], far_base[a]);
                t_near = t0 > t_near ? t0 : t_near;
                t_far = t1 < t_far ? t1 : t_far;
            }
            near[s] = t_near;
            if (t_near <= t_far) mask |= 1u << s;
        }
        return mask;
    }
    // Keys as simd::distance_key makes them, sorted by insertion.
    RF_HDI void sort(const float* near, unsigned mask, uint32_t* keys) const {
        int count = 0;
        for (int s = 0; s < kCwbvhWidth; ++s) {
            if (!((mask >> s) & 1u)) continue;
            const uint32_t key = (float_to_bits(near[s]) & ~7u) | uint32_t(s);
            int j = count++;
            for (; j > 0 && keys[j - 1] > key; --j) keys[j] = keys[j - 1];
            keys[j] = key;
        }
    }
};

struct PageLeafTest {
    WatertightRay ray;
    static RF_HDI PageLeafTest make(const Ray& world) { return {WatertightRay::make(world)}; }

    template <bool kAnyHit>
    RF_HDI bool test(const Quad* quads, uint32_t first, uint32_t count, uint32_t page, const PageInfo& info,
                     float tmin, Hit& hit) const {
        bool found = false;
        for (uint32_t q = first; q < first + count; ++q)
            for (int half = 0; half < 2; ++half) {
                TriangleHit th;
                if (!intersect_triangle(ray, decoded_quad_half(quads[q], half, info), tmin, hit.t, th)) continue;
                hit.t = th.t;
                hit.u = th.u;
                hit.v = th.v;
                hit.prim = page * kTrianglesPerPageSlot + 2 * q + uint32_t(half);
                found = true;
                if (kAnyHit) return true;
            }
        return found;
    }
};
#endif

// A node's test: the slots the ray enters before tmax, and where.
struct NodeHits {
    unsigned mask = 0;
    alignas(32) float near[kCwbvhWidth];
};

// Walks a wide tree (a page's BVH or the top BVH), nearer children first,
// never past tmax (read again after every leaf: it shrinks as hits are
// found). leaf(first, count) handles a leaf's items and returns true to end
// the walk (an any-hit query's hit). `visits` counts the nodes fetched.
// `root_hits`, when given, is the root's test already made (a page's root
// is tested from its resident copy before the page is touched). The tree
// was checked when it was read (check_wide_tree): at most kCwbvhMaxDepth
// levels, so the stack cannot overflow.
template <typename Leaf>
RF_HDI void walk_wide_tree(const PageNode* nodes, const PageNodeTest& test, const float& tmax, uint32_t& visits,
                           Leaf&& leaf, const NodeHits* root_hits = nullptr) {
    PendingNode stack[kPageStackSize];
    int top = 0;
    uint32_t ref = 0;  // the root
    for (;;) {
        // Down the nearest hit children until a leaf or a node whose children are all missed.
        while (!(ref & kPageLeafRef)) {
            const PageNode& n = nodes[ref];
            alignas(32) float near_here[kCwbvhWidth];
            const float* near = near_here;
            unsigned mask;
            if (root_hits && ref == 0) {
                mask = root_hits->mask;
                near = root_hits->near;
            } else {
                ++visits;
                mask = test.hits(n, tmax, near_here);
            }
            if (mask == 0) break;
            if (cwbvh_popc(mask) == 1) {
                ref = page_child_ref(n, int(cwbvh_popc(mask - 1)));
                continue;
            }
            uint32_t keys[kCwbvhWidth];
            test.sort(near, mask, keys);
            // The farther ones wait, farthest deepest; the nearest is next.
            for (int i = int(cwbvh_popc(mask)) - 1; i > 0; --i)
                stack[top++] = {page_child_ref(n, int(keys[i] & 7u)), near[keys[i] & 7u]};
            ref = page_child_ref(n, int(keys[0] & 7u));
        }
        if ((ref & kPageLeafRef) && leaf((ref & ~kPageLeafRef) >> 2, ref & 3u)) return;
        // Back to the nearest waiting child the ray still reaches before tmax.
        for (;;) {
            if (top == 0) return;
            const PendingNode p = stack[--top];
            if (p.entry <= rf::detail::widen_far(tmax)) {
                ref = p.node;
                break;
            }
        }
    }
}

// Searches one cached page; true when `hit` got closer (or, any-hit, when
// anything was hit).
// (`node_test`: the ray in the page's space; `root_hits`: its root's test.)
template <bool kAnyHit>
RF_HDI bool search_page(const uint8_t* bytes, const PageInfo& info, uint32_t page, const Ray& world,
                        const PageNodeTest& node_test, const NodeHits& root_hits, const PageLeafTest& leaf_test,
                        Hit& hit, PagedCounters& counters) {
    GeometryPageHeader header;
    memcpy(&header, bytes, sizeof(header));
    const auto* nodes = reinterpret_cast<const PageNode*>(bytes + sizeof(header));
    const auto* quads = reinterpret_cast<const Quad*>(bytes + sizeof(header) + header.node_count * sizeof(PageNode));
    bool found = false;
    walk_wide_tree(
        nodes, node_test, hit.t, counters.nodes,
        [&](uint32_t first, uint32_t count) {
            counters.quads += count;
            if (!leaf_test.template test<kAnyHit>(quads, first, count, page, info, world.tmin, hit)) return false;
            found = true;
            return kAnyHit;
        },
        &root_hits);
    return found;
}

// The ray in a page's quantised space: |quantised coordinates| stay below
// 2^15; boxes grown by 2 units (see WideBoxRay).
RF_HDI PageNodeTest page_node_test(const WideBoxRay& box, const PageInfo& info) {
    return PageNodeTest::make(box.to_page(info.offset, info.scale, 2.0f, 32768.0f));
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

// `ray` in the object space of `instance`.
RF_HDI Ray object_ray(const InstanceInfo& instance, const Ray& ray) {
    const float* m = instance.object_from_world;
    Ray r = ray;
    r.org = Vec3f(m[0] * ray.org.x + m[1] * ray.org.y + m[2] * ray.org.z + m[3],
                  m[4] * ray.org.x + m[5] * ray.org.y + m[6] * ray.org.z + m[7],
                  m[8] * ray.org.x + m[9] * ray.org.y + m[10] * ray.org.z + m[11]);
    r.dir = Vec3f(m[0] * ray.dir.x + m[1] * ray.dir.y + m[2] * ray.dir.z,
                  m[4] * ray.dir.x + m[5] * ray.dir.y + m[6] * ray.dir.z,
                  m[8] * ray.dir.x + m[9] * ray.dir.y + m[10] * ray.dir.z);
    return r;
}

// The largest |coordinate| of a box (sizes WideBoxRay's guards).
RF_HDI float box_scale(const Box3f& b) {
    float s = 0.0f;
    for (int a = 0; a < 3; ++a) {
        const float lo = fabsf(b.lo[a]), hi = fabsf(b.hi[a]);
        s = lo > s ? lo : s;
        s = hi > s ? hi : s;
    }
    return s;
}

// A ray's visit of the pages it meets in one iteration: cached pages are
// searched, the first missing one is requested (see the file's comment).
struct PageVisit {
    const PagedSceneView& v;
    const Ray& ray;
    PagedRayState& state;
    PagedCounters& counters;
    uint32_t restart = 0;          // the ray's restart point should a page be requested now
    WideBoxRay box;                // the world ray's box test ...
    PageLeafTest leaf_test;        // ... and triangle test, for every page
    PageMailbox mailbox;
    bool requested = false;        // a missing page is (closest hit) or will be (any hit) requested
    uint32_t deferred_page = 0;    // the first missing page (any hit: requested only if no cached page blocks the ray)

    // Top reference `r`: its page as it lies, or through its instance.
    // True when an any-hit query found a hit (the ray is then finished).
    template <bool kAnyHit>
    RF_HDI bool visit_ref(uint32_t r) {
        const TopRef ref = v.refs[r];
        const uint32_t page = ref.page;
        const uint32_t d = v.geometry.descriptor(page);
        // WasRead stays per page: in the iteration it was cached, every ray
        // searched it through every reference it met.
        if ((d & kWasRead) || mailbox.seen(r)) return false;
        // The page's root from its resident copy: a ray that enters none of
        // its children needs nothing of the page, cached or not (about half
        // of the rays that cross a page's bounds, on the generated scenes).
        const PageInfo& info = v.pages[page];
        Ray local;
        if (ref.instance != kNoInstance) local = object_ray(v.instances[ref.instance], ray);
        const Ray& page_ray = ref.instance == kNoInstance ? ray : local;
        const PageNodeTest node_test = page_node_test(
            ref.instance == kNoInstance ? box : WideBoxRay::make(local, 0.0f, box_scale(info.bounds)), info);
        NodeHits root;
        ++counters.nodes;
        root.mask = node_test.hits(v.page_roots[page], state.hit.t, root.near);
        if (root.mask == 0) return false;
        if (d & kOutOfCore) {
            if (!requested) {
                if (!kAnyHit) v.geometry.request(page);
                deferred_page = page;
                requested = true;
                state.restart = restart;
            }
            return false;
        }
        v.geometry.request(page);  // a use, for the LFU counts
        mailbox.add(r);
        ++counters.pages;
        const uint8_t* bytes = v.geometry.slots + uint64_t(d & kSlotMask) * v.geometry.slot_bytes;
        // An instanced page: in the object's space (t is unchanged by the
        // affine map), where the page's decode transform applies; triangles
        // tested there.
        const bool hit = search_page<kAnyHit>(
            bytes, info, page, page_ray, node_test, root,
            ref.instance == kNoInstance ? leaf_test : PageLeafTest::make(local), state.hit, counters);
        if (!hit) return false;
        state.instance = ref.instance;
        if (!kAnyHit) return false;
        state.occluded = 1;
        state.restart = kRayFinished;
        return true;
    }

    // The end of the iteration: true when the ray asked for a page and must run again.
    template <bool kAnyHit>
    RF_HDI bool finish() {
        if (!requested) {
            state.restart = kRayFinished;
            state.waiting_for = kNotWaiting;
            return false;
        }
        if (kAnyHit) v.geometry.request(deferred_page);  // no cached page blocked the ray
        state.waiting_for = deferred_page;
        return true;
    }
};

// TopLevel::Grid: one ray's walk of a cell's middle BVH, nearer child first.
struct CellVisit {
    const PagedSceneView& v;
    const Ray& ray;
    const rf::detail::SlabRay& slab;
    PageVisit& pages;

    // True when an any-hit query found a hit (the ray is then finished).
    template <bool kAnyHit>
    RF_HDI bool walk(uint32_t root, uint32_t cell) {
        PendingNode stack[kBvhMaxDepth];
        int top = 0;
        float entry;
        PagedCounters& counters = pages.counters;
        const float& tmax = pages.state.hit.t;
        pages.restart = cell;
        ++counters.middle;
        if (!rf::detail::slab_test(slab, v.middle_nodes[root].bounds, ray.tmin, tmax, entry)) return false;
        uint32_t node = root;
        for (;;) {
            const BvhNode& n = v.middle_nodes[node];
            if (n.is_leaf()) {
                if (pages.visit_ref<kAnyHit>(n.first)) return true;
            } else {
                counters.middle += 2;
                float e0, e1;
                const bool h0 = rf::detail::slab_test(slab, v.middle_nodes[n.first].bounds, ray.tmin, tmax, e0);
                const bool h1 = rf::detail::slab_test(slab, v.middle_nodes[n.first + 1].bounds, ray.tmin, tmax, e1);
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
                if (p.entry <= rf::detail::widen_far(tmax)) {
                    node = p.node;
                    break;
                }
            }
        }
    }
};

// TopLevel::WideBvh: one iteration walks the whole top BVH (culled by the
// nearest hit so far); pages searched in earlier iterations are WasRead
// and skipped, so a restart is always at the root.
inline constexpr uint32_t kRestartAtRoot = 0;

template <bool kAnyHit>
RF_HDI bool top_bvh_iteration(const PagedSceneView& v, const Ray& ray, PagedRayState& state,
                              PagedCounters& counters) {
    PageVisit visit{v,  ray, state, counters, kRestartAtRoot, WideBoxRay::make(ray, 0.0f, v.coord_scale),
                    PageLeafTest::make(ray), PageMailbox{}, false, 0};
    const PageNodeTest test = PageNodeTest::make(visit.box);
    bool blocked = false;
    walk_wide_tree(v.top_nodes, test, state.hit.t, counters.middle, [&](uint32_t first, uint32_t count) {
        for (uint32_t i = first; i < first + count; ++i)
            if (visit.visit_ref<kAnyHit>(i)) return blocked = true;
        return false;
    });
    return blocked ? false : visit.finish<kAnyHit>();
}

// TopLevel::Grid: the 3D-DDA from the restart cell (the first cell of a fresh ray).
template <bool kAnyHit>
RF_HDI bool grid_iteration(const PagedSceneView& v, const Ray& ray, PagedRayState& state, PagedCounters& counters,
                           bool fresh) {
    int start[3];
    if (fresh) {
        if (!start_cell(v, ray, state.hit.t, start)) {
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
    PageVisit pages{v,   ray, state, counters, 0, WideBoxRay::make(ray, 0.0f, v.coord_scale), PageLeafTest::make(ray),
                    PageMailbox{}, false, 0};
    CellVisit visit{v, ray, slab, pages};
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
    return pages.finish<kAnyHit>();
}

// Whether a ray that asked for `waiting_for` in its last run has anything to
// do now: its page came in, or the ray passes through one of the pages the
// last swap loaded (their bounds, before its nearest hit). If not, its run
// would search nothing (the other cached pages are WasRead or already
// searched by it) and ask for the same page again: it only asks again.
// Every pending ray still searches every page cached in an iteration that
// lies on its way, so WasRead keeps its meaning; the ray just skips the top
// level's walk (at a 1/100 cache, 80 % of its runs).
RF_HDI bool has_news(const PagedSceneView& v, const Ray& ray, const PagedRayState& state, const FreshPages& fresh) {
    if (fresh.count > kMaxFreshPages || !(v.geometry.descriptor(state.waiting_for) & kOutOfCore)) return true;
    if (fresh.count == 0) return false;
    const rf::detail::SlabRay slab = rf::detail::SlabRay::make(ray);
    for (uint32_t i = 0; i < fresh.count; ++i) {
        const PageInfo& page = v.pages[fresh.pages[i]];
        float entry;
        // An instanced page's bounds are in its object's space: run.
        if (page.instanced || rf::detail::slab_test(slab, page.bounds, ray.tmin, state.hit.t, entry)) return true;
    }
    return false;
}

}  // namespace detail

// One iteration of one ray (see above). Returns true when the ray asked for
// a page and must run again after the page manager's swap.
// `fresh`: the pages the last swap loaded (FreshPages).
template <bool kAnyHit>
RF_HD bool paged_iteration(const PagedSceneView& v, const Ray& ray, PagedRayState& state, PagedCounters& counters,
                           const FreshPages& fresh) {
    if (state.restart == kRayFinished) return false;
    if (state.waiting_for != kNotWaiting && !detail::has_news(v, ray, state, fresh)) {
        v.geometry.request(state.waiting_for);
        return true;
    }
    ++counters.runs;
    const bool first_run = state.restart == kRayNotStarted;
    if (first_run) {
        // A ray with a non-finite origin or direction meets nothing (and an
        // infinite tmax is the largest float), so the walk always ends.
        const bool finite = fabsf(ray.org.x) <= kInfinity && fabsf(ray.org.y) <= kInfinity &&
                            fabsf(ray.org.z) <= kInfinity && fabsf(ray.dir.x) <= kInfinity &&
                            fabsf(ray.dir.y) <= kInfinity && fabsf(ray.dir.z) <= kInfinity;
        state.hit.t = fminf(ray.tmax, kInfinity);
        if (v.page_count == 0 || !finite) {
            state.restart = kRayFinished;
            return false;
        }
    }
    return v.top_nodes ? detail::top_bvh_iteration<kAnyHit>(v, ray, state, counters)
                       : detail::grid_iteration<kAnyHit>(v, ray, state, counters, first_run);
}

}  // namespace rf::pack
