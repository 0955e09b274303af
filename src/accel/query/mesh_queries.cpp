// MeshQueries on the CPU (rayforge/accel/mesh_queries.h): every hit of a
// ray, the closest point, the generalised winding number, over one
// canonical BVH built by the project's builders (build_bvh_on_cpu).
//
//  - Every hit: the BVH traversal of all_hits.h (Ize 2013's slab test,
//    Woop, Benthin and Wald 2013's watertight triangle test, as
//    trace/bvh_traversal.h) without the shrinking interval; the hits of one
//    ray sorted by (t, prim), then merge_shared_hits() keeps one hit per
//    crossing of a shared edge or vertex.
//  - Closest point: a BVH point query over the BVH collapsed to 8-wide
//    nodes and 4-triangle packs (closest_point_wide.h; closest_point.h has
//    the binary reference): nearest children first, pruned by the best
//    squared distance so far; per triangle Ericson, "Real-Time Collision
//    Detection" (2005), 5.1.5, four at a time. A batch is
//    answered in the Morton order of its points (spatial_order), each query
//    seeded with the previous one's triangle: a random batch over a large
//    mesh otherwise misses the cache at nearly every node (measured on the
//    Dragon: 69 nodes and 7 us per query near the surface, in input order).
//  - Winding numbers: Jacobson, Kavan and Sorkine-Hornung 2013 evaluated by
//    Barill, Dickson, Schmidt, Levin and Jacobson 2018's hierarchical
//    expansion (winding_number.cpp).
//
// Data layout: the canonical Bvh (its prim_indices index the caller's
// triangles) and a copy of the triangles in leaf-slot order with their
// index and a zero-area flag (query_mesh.h, 40 bytes each), so leaves read
// contiguous memory; the 8-wide BVH (wide_bvh.h: 256-byte nodes, 160-byte
// packs of four triangles); a 112-byte WindingNode per BVH node; one weight per
// slot only where a builder with spatial splits (sbvh, gridbvh-split)
// referenced a triangle from several leaves (1 / its references, so the
// winding number counts it once). The caller's triangles are not kept.
//
// Parallelism (TBB via core/parallel.h): every batch is one for_range over
// its queries on the calling thread's arena (points: in Morton order). A
// list of all hits is made in fixed blocks of rays (each block's hits into
// its own array), then the per-ray counts are summed into ray_splits and
// the blocks copied into place in parallel. The build and the refit run the
// builder, refit_bvh and the winding pass on the arena of BuildOptions::threads
// (build) or the caller's (refit).
//
// Determinism: each query is answered by one thread in a fixed traversal
// order, the ties are broken by rules that depend only on the set of
// candidates (closest point: the smallest prim; hits: merge_shared_hits),
// and the block layout of the hit lists does not depend on the scheduling,
// so every answer is the same for any thread count.
#include "rayforge/accel/mesh_queries.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/builders/morton_code.h"
#include "accel/bvh/refit.h"
#include "accel/query/all_hits.h"
#include "accel/query/closest_point.h"
#include "accel/query/closest_point_wide.h"
#include "accel/query/query_mesh.h"
#include "accel/query/winding_number.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace query {

void fill_slot_triangles(const Bvh& bvh, std::span<const Triangle> triangles, std::vector<SlotTriangle>& slots) {
    slots.resize(bvh.prim_indices.size());
    parallel::for_range(size_t(0), slots.size(), size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t s = lo; s < hi; ++s) {
            const uint32_t prim = bvh.prim_indices[s];
            const Triangle& t = triangles[prim];
            const Vec3f n = t.geometric_normal();
            const bool zero = n.x == 0.0f && n.y == 0.0f && n.z == 0.0f;
            slots[s] = {t, prim | (zero ? kZeroAreaBit : 0u)};
        }
    });
}

void merge_shared_hits(std::vector<SlotHit>& hits, const SlotTriangle* slots) {
    std::sort(hits.begin(), hits.end(), [&](const SlotHit& a, const SlotHit& b) {
        return a.t < b.t || (a.t == b.t && slots[a.slot].prim() < slots[b.slot].prim());
    });
    auto close = [](float a, float b) {
        return std::fabs(a - b) <= 1e-6f * std::max(1.0f, std::max(std::fabs(a), std::fabs(b)));
    };
    auto share_vertex = [](const Triangle& a, const Triangle& b) {
        for (const Vec3f& p : {a.v0, a.v1, a.v2}) {
            if (p == b.v0 || p == b.v1 || p == b.v2) return true;
        }
        return false;
    };
    // i is dropped when j (before i in (prim, position) order) is close and shares a vertex.
    auto drops = [&](size_t j, size_t i) {
        const uint32_t pj = slots[hits[j].slot].prim(), pi = slots[hits[i].slot].prim();
        if (pj > pi || (pj == pi && j > i)) return false;
        return share_vertex(slots[hits[j].slot].tri, slots[hits[i].slot].tri);
    };
    std::vector<uint8_t> dropped(hits.size(), 0);
    for (size_t i = 0; i < hits.size(); ++i) {
        // Sorted by t, and |dt| - 1e-6 max(1, |t|, |t'|) grows with the gap: stop at the first pair too far apart.
        for (size_t j = i; j-- > 0 && close(hits[j].t, hits[i].t) && !dropped[i];) dropped[i] = drops(j, i);
        for (size_t j = i + 1; j < hits.size() && close(hits[j].t, hits[i].t) && !dropped[i]; ++j) dropped[i] = drops(j, i);
    }
    size_t kept = 0;
    for (size_t i = 0; i < hits.size(); ++i) {
        if (!dropped[i]) hits[kept++] = hits[i];
    }
    hits.resize(kept);
}

}  // namespace query

namespace {

using query::SlotHit;
using query::SlotTriangle;

constexpr size_t kMaxTriangles = 0x7FFFFFFF;  // indices below 2^31 (query::kZeroAreaBit)
constexpr size_t kPointGrain = 64;            // queries per task
constexpr size_t kRayGrain = 32;
constexpr size_t kRayBlock = 256;             // rays per block of a hit list

constexpr size_t kOrderedBatch = 1024;        // smaller point batches run in input order

// The order in which to answer point queries: by the 30-bit Morton code of
// each point in the batch's bounds (non-finite points last), then by index,
// so that one thread's consecutive queries share nodes and triangles.
std::vector<uint32_t> spatial_order(std::span<const Vec3f> points) {
    std::vector<uint32_t> order(points.size());
    if (points.size() < kOrderedBatch) {
        for (size_t i = 0; i < order.size(); ++i) order[i] = uint32_t(i);
        return order;
    }
    const Box3f box = parallel::reduce(
        size_t(0), points.size(), size_t(16384), Box3f{},
        [&](size_t lo, size_t hi, Box3f b) {
            for (size_t i = lo; i < hi; ++i) {
                if (is_finite(points[i])) b.extend(points[i]);
            }
            return b;
        },
        [](const Box3f& a, const Box3f& b) { return merge(a, b); });
    const MortonQuantizer quantizer(box, 10);
    std::vector<uint64_t> keys(points.size());
    parallel::for_range(size_t(0), points.size(), size_t(16384), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const uint64_t code = is_finite(points[i]) ? quantizer.code30(points[i]) : (1u << 30);
            keys[i] = code << 32 | i;
        }
    });
    parallel::sort(keys, std::less<uint64_t>());
    for (size_t i = 0; i < keys.size(); ++i) order[i] = uint32_t(keys[i]);
    return order;
}

void check_triangles(std::span<const Triangle> triangles, const char* what) {
    if (triangles.size() > kMaxTriangles) {
        throw Error(std::string(what) + ": " + std::to_string(triangles.size()) + " triangles exceed the limit of " +
                    std::to_string(kMaxTriangles));
    }
    for (size_t i = 0; i < triangles.size(); ++i) {
        const Triangle& t = triangles[i];
        if (!is_finite(t.v0) || !is_finite(t.v1) || !is_finite(t.v2)) {
            throw Error(std::string(what) + ": triangle " + std::to_string(i) + " has a non-finite coordinate");
        }
    }
}

template <class T, class U>
void check_sizes(std::span<T> queries, std::span<U> out, const char* what) {
    if (queries.size() != out.size()) {
        throw Error(std::string(what) + ": " + std::to_string(out.size()) + " outputs for " +
                    std::to_string(queries.size()) + " queries");
    }
}

class CpuMeshQueries final : public MeshQueries {
public:
    CpuMeshQueries(std::span<const Triangle> triangles, const BuildOptions& options) : size_(triangles.size()) {
        if (triangles.empty()) return;
        bvh_ = build_bvh_on_cpu(triangles, options);
        plan_ = make_refit_plan(bvh_);
        // Spatial splits may reference a triangle from several leaves.
        std::vector<uint32_t> refs(triangles.size(), 0);
        bool shared = false;
        for (const uint32_t prim : bvh_.prim_indices) shared |= ++refs[prim] > 1;
        if (shared) {
            weights_.resize(bvh_.prim_indices.size());
            for (size_t s = 0; s < weights_.size(); ++s) weights_[s] = 1.0f / float(refs[bvh_.prim_indices[s]]);
        }
        update_derived(triangles);
    }

    void list_intersections(std::span<const Ray> rays, AllHits& out) const override {
        const size_t blocks = (rays.size() + kRayBlock - 1) / kRayBlock;
        std::vector<std::vector<Hit>> block_hits(blocks);
        out.ray_splits.assign(rays.size() + 1, 0);
        parallel::for_range(size_t(0), blocks, size_t(1), [&](size_t lo, size_t hi) {
            std::vector<SlotHit> scratch;
            for (size_t b = lo; b < hi; ++b) {
                const size_t end = std::min(rays.size(), (b + 1) * kRayBlock);
                for (size_t i = b * kRayBlock; i < end; ++i) {
                    ray_hits(rays[i], scratch);
                    out.ray_splits[i + 1] = uint32_t(scratch.size());
                    for (const SlotHit& h : scratch) block_hits[b].push_back({h.t, h.u, h.v, slots_[h.slot].prim()});
                }
            }
        });
        for (size_t i = 0; i < rays.size(); ++i) out.ray_splits[i + 1] += out.ray_splits[i];
        const size_t total = out.ray_splits.back();
        out.hits.resize(total);
        out.ray_ids.resize(total);
        parallel::for_range(size_t(0), blocks, size_t(1), [&](size_t lo, size_t hi) {
            for (size_t b = lo; b < hi; ++b) {
                const size_t first_ray = b * kRayBlock, end = std::min(rays.size(), first_ray + kRayBlock);
                std::copy(block_hits[b].begin(), block_hits[b].end(), out.hits.begin() + out.ray_splits[first_ray]);
                for (size_t i = first_ray; i < end; ++i) {
                    std::fill(out.ray_ids.begin() + out.ray_splits[i], out.ray_ids.begin() + out.ray_splits[i + 1],
                              uint32_t(i));
                }
            }
        });
    }

    void count_intersections(std::span<const Ray> rays, std::span<uint32_t> counts) const override {
        check_sizes(rays, counts, "count_intersections");
        parallel::for_range(size_t(0), rays.size(), kRayGrain, [&](size_t lo, size_t hi) {
            std::vector<SlotHit> scratch;
            for (size_t i = lo; i < hi; ++i) {
                ray_hits(rays[i], scratch);
                counts[i] = uint32_t(scratch.size());
            }
        });
    }

    void closest_points(std::span<const Vec3f> queries, std::span<ClosestPoint> out) const override {
        check_sizes(queries, out, "closest_points");
        const query::WidePointView wide_view{wide_.nodes.empty() ? nullptr : wide_.nodes.data(), wide_.packs.data(),
                                             view(), slot_of_prim_.data()};
        const std::vector<uint32_t> order = spatial_order(queries);
        parallel::for_range(size_t(0), queries.size(), kPointGrain, [&](size_t lo, size_t hi) {
            uint32_t seed = kInvalidId;
            for (size_t k = lo; k < hi; ++k) {
                const size_t i = order[k];
                ClosestPoint& c = out[i];
                const Vec3f q = queries[i];
                const query::PointQueryResult r =
                    is_finite(q) ? query::wide_closest_point_query(wide_view, q, seed) : query::PointQueryResult{};
                seed = r.slot;
                if (r.prim == kInvalidId) {
                    c = ClosestPoint{Vec3f(std::numeric_limits<float>::quiet_NaN()), kInvalidId, 0.0f, 0.0f};
                } else {
                    c = ClosestPoint{r.point.point, r.prim, r.point.u, r.point.v};
                }
            }
        });
    }

    void winding_numbers(std::span<const Vec3f> queries, std::span<float> out, float beta) const override {
        check_sizes(queries, out, "winding_numbers");
        const query::QueryView view = this->view();
        const bool exact = !(beta > 0.0f);
        const float beta2 = exact ? 0.0f : beta * beta;
        const float* weights = weights_.empty() ? nullptr : weights_.data();
        const std::vector<uint32_t> order = spatial_order(queries);
        parallel::for_range(size_t(0), queries.size(), kPointGrain, [&](size_t lo, size_t hi) {
            for (size_t k = lo; k < hi; ++k) {
                const size_t i = order[k];
                const Vec3f q = queries[i];
                out[i] = is_finite(q) ? query::winding_number_query(view, winding_.data(), weights, q, beta2, exact)
                                      : std::numeric_limits<float>::quiet_NaN();
            }
        });
    }

    void refit(std::span<const Triangle> triangles) override {
        if (triangles.size() != size_) {
            throw Error("MeshQueries::refit: " + std::to_string(triangles.size()) + " triangles for a mesh of " +
                        std::to_string(size_));
        }
        check_triangles(triangles, "MeshQueries::refit");
        if (bvh_.nodes.empty()) return;
        refit_bvh(bvh_, triangles, plan_);
        update_derived(triangles);
    }

    [[nodiscard]] size_t size() const override { return size_; }
    [[nodiscard]] const Bvh& bvh() const override { return bvh_; }

private:
    [[nodiscard]] query::QueryView view() const {
        return {bvh_.nodes.data(), slots_.data(), uint32_t(bvh_.nodes.size())};
    }

    // The slot copy, the 8-wide BVH of the point queries and the winding
    // expansions of the current triangles.
    void update_derived(std::span<const Triangle> triangles) {
        query::fill_slot_triangles(bvh_, triangles, slots_);
        wide_ = collapse_bvh<8>(bvh_, std::vector<Triangle>(triangles.begin(), triangles.end()));
        if (slot_of_prim_.empty()) {
            slot_of_prim_.assign(size_, kInvalidId);
            for (uint32_t s = uint32_t(slots_.size()); s-- > 0;) slot_of_prim_[slots_[s].prim()] = s;
        }
        query::compute_winding_nodes(bvh_, slots_, weights_, winding_);
    }

    // One ray's hits, merged (ray_hits.size() is its count).
    void ray_hits(const Ray& ray, std::vector<SlotHit>& hits) const {
        hits.clear();
        if (!query::ray_can_hit(ray)) return;
        query::for_each_hit(view(), ray, [&](const SlotHit& h) { hits.push_back(h); });
        query::merge_shared_hits(hits, slots_.data());
    }

    size_t size_ = 0;
    Bvh bvh_;
    RefitPlan plan_;
    std::vector<SlotTriangle> slots_;
    WideBvh<8> wide_;                      // closest points: collapsed from bvh_ (its topology fixed by refit too)
    std::vector<uint32_t> slot_of_prim_;   // a slot of each triangle (the packs' scalar fallback)
    std::vector<float> weights_;  // per slot, empty when every triangle has one reference
    std::vector<query::WindingNode> winding_;
};

}  // namespace

std::unique_ptr<MeshQueries> MeshQueries::build(std::span<const Triangle> triangles, const BuildOptions& build) {
    BuildOptions options = build;
    options.structure = Structure::Bvh;
    options.device = Device{};
    validate_build_options(options);
    check_triangles(triangles, "MeshQueries::build");
    return parallel::with_threads(options.threads, [&]() -> std::unique_ptr<MeshQueries> {
        return std::make_unique<CpuMeshQueries>(triangles, options);
    });
}

}  // namespace rf
