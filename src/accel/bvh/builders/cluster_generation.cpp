// Cluster generation for cluster-based BVH builds (Garanzha 2014, ch. 3;
// Garanzha 2009, "The Use of Precomputed Triangle Clusters for Accelerated
// Ray Tracing in Dynamic Scenes", EGSR 2009).
//
// Heuristics: Acc(k) = reg(k) - sizeBound(k) * regBound(k), eqs. 3.1-3.8;
// Naive(k) = sum of triangle areas / surface area of the cluster's box.
// The gaps the text leaves are resolved as follows:
//  - S(k), the bounding sphere, is the box-centred sphere: centre = centre of
//    the box of the cluster's distinct vertices, radius = the largest
//    distance from it to one of them (within sqrt(3) of the optimum; exact
//    and order-independent, unlike Ritter's, so merges are symmetric);
//  - N_AVG falls back to the unit normal of the largest triangle (lowest id
//    on ties) when the unit normals' sum is shorter than 1e-3 per triangle;
//    degenerate triangles have a zero normal and no area;
//  - AvgSA = 4 pi r^2 with r the mean of the triangles' sphere radii;
//  - a cluster never grows beyond kMaxClusterTriangles (64) triangles, the
//    wide BVH collapse's largest leaf;
//  - the merge queue has 4096 buckets over [-2, 2] (granularity 1/1024),
//    each a binary heap, so contraction is in exact key order (ties: the
//    lower pair of cluster ids) and the bucket count only affects speed;
//    stale entries are skipped lazily by per-cluster versions;
//  - Acc merges while the best edge has Acc > 0 (so every cluster of two or
//    more triangles has Acc > 0); Acc grows while the best candidate has
//    Acc > 0;
//  - Naive has no stopping rule of its own: as in the text's comparison, it
//    stops at the cluster count Acc gives with the same generation (merging
//    contracts the best edge until that count; growing grows clusters to
//    the mean size of Acc's clusters).
//
// Data layout: per triangle, area and unit normal; the dual graph in CSR
// (dual_graph below); during generation, per cluster its triangles, its
// sorted distinct vertex indices, vertex box, unit-normal sum, largest
// triangle and (merging) its sorted cluster neighbours. The result is the
// compressed ClusterPartition of cluster_generation.h.
//
// Parallelism: per-triangle data, the dual graph and the initial edge keys
// are computed by parallel loops (core/parallel.h); meshes are
// clustered in parallel. Merging and growing are sequential.
//
// Determinism: every parallel loop writes its own slots; the sequential
// parts break ties by ids and the growing order comes from a Fisher-Yates
// permutation drawn from ClusterOptions::seed with std::mt19937_64, so the
// result is the same for any thread count and standard library.
#include "accel/bvh/builders/cluster_generation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <string>

#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr float kNoMerge = -std::numeric_limits<float>::infinity();

// ---- Per-triangle data.

struct MeshData {
    std::span<const Vec3f> positions;
    std::span<const uint32_t> indices;
    std::vector<float> area;
    std::vector<Vec3f> normal;   // unit, or zero for a degenerate triangle
    std::vector<Vec4f> normal_area;  // (normal, area) packed: Acc's projected-area loop reads one line per triangle
    double avg_sphere_area = 0;  // AvgSA
};

Vec3f corner(const MeshData& m, uint32_t t, int k) { return m.positions[m.indices[3 * size_t{t} + k]]; }

MeshData mesh_data(std::span<const Vec3f> positions, std::span<const uint32_t> indices) {
    MeshData m{positions, indices, {}, {}, {}, 0.0};
    const uint32_t n = static_cast<uint32_t>(indices.size() / 3);
    for (uint32_t i : indices) {
        if (i >= positions.size()) throw Error("clusters: vertex index " + std::to_string(i) + " out of range");
    }
    m.area.resize(n);
    m.normal.resize(n);
    std::vector<float> radius(n);
    parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
        for (uint32_t t = lo; t < hi; ++t) {
            const Vec3f a = corner(m, t, 0), b = corner(m, t, 1), c = corner(m, t, 2);
            const Vec3f g = cross(b - a, c - a);
            const float len = length(g);
            m.area[t] = 0.5f * len;
            m.normal[t] = len > 0.0f && std::isfinite(len) ? g * (1.0f / len) : Vec3f(0.0f);
            Box3f box;
            box.extend(a), box.extend(b), box.extend(c);
            const Vec3f o = box.center();
            radius[t] = std::sqrt(std::max({length_squared(a - o), length_squared(b - o), length_squared(c - o)}));
        }
    });
    m.normal_area.resize(n);
    for (uint32_t t = 0; t < n; ++t) m.normal_area[t] = Vec4f{m.normal[t].x, m.normal[t].y, m.normal[t].z, m.area[t]};
    double sum = 0.0;
    for (float r : radius) sum += r;  // sequential: the same sum for any thread count
    const double r = n ? sum / n : 0.0;
    m.avg_sphere_area = 4.0 * kPi * r * r;
    return m;
}

// ---- Clusters under construction and their heuristics.

struct Cluster {
    std::vector<uint32_t> tris;
    std::vector<uint32_t> verts;  // sorted distinct vertex indices
    std::vector<uint32_t> adj;    // merging: sorted neighbouring clusters
    Box3f box;
    Vec3f normal_sum{0.0f};
    float area = 0.0f;
    uint32_t largest = 0;
    uint32_t version = 0;
    bool alive = true;
};

void make_singleton(const MeshData& m, uint32_t t, Cluster& c) {
    c.tris.assign(1, t);
    c.verts.assign({m.indices[3 * size_t{t}], m.indices[3 * size_t{t} + 1], m.indices[3 * size_t{t} + 2]});
    std::sort(c.verts.begin(), c.verts.end());
    c.verts.erase(std::unique(c.verts.begin(), c.verts.end()), c.verts.end());
    c.box = Box3f{};
    for (uint32_t v : c.verts) c.box.extend(m.positions[v]);
    c.normal_sum = m.normal[t];
    c.area = m.area[t];
    c.largest = t;
    c.version = 0;
    c.alive = true;
}

size_t union_count(const std::vector<uint32_t>& a, const std::vector<uint32_t>& b) {
    size_t i = 0, j = 0, n = 0;
    while (i < a.size() && j < b.size()) {
        const uint32_t x = a[i], y = b[j];
        i += x <= y;
        j += y <= x;
        ++n;
    }
    return n + (a.size() - i) + (b.size() - j);
}

uint32_t larger_triangle(const MeshData& m, uint32_t s, uint32_t t) {
    return m.area[t] > m.area[s] || (m.area[t] == m.area[s] && t < s) ? t : s;
}

// Scores the union of one or two clusters (b may be null).
class Scorer {
public:
    Scorer(const MeshData& m, const ClusterOptions& o) : m_(m), o_(o) {}

    [[nodiscard]] float score(const Cluster& a, const Cluster* b) const {
        if (a.tris.size() + (b ? b->tris.size() : 0) > kMaxClusterTriangles) return kNoMerge;
        return static_cast<float>(o_.heuristic == ClusterHeuristic::Naive ? naive(a, b) : acc(a, b));
    }
    // Whether an edge of this key may ever be contracted (Acc: only
    // acceptable clusters; Naive: anything, it stops at a count).
    [[nodiscard]] bool mergeable(float key) const {
        return o_.heuristic == ClusterHeuristic::Naive ? key > kNoMerge : key > 0.0f;
    }

    [[nodiscard]] double naive(const Cluster& a, const Cluster* b) const {
        const Box3f box = b ? merge(a.box, b->box) : a.box;
        const double sa = box.surface_area();
        return sa > 0.0 ? (double(a.area) + (b ? b->area : 0.0f)) / sa : 0.0;
    }

    [[nodiscard]] double acc(const Cluster& a, const Cluster* b) const {
        const Box3f box = b ? merge(a.box, b->box) : a.box;
        const Vec3f centre = box.center();
        float r2 = 0.0f;  // S(k): the box-centred sphere
        for (uint32_t v : a.verts) r2 = std::max(r2, length_squared(m_.positions[v] - centre));
        if (b) for (uint32_t v : b->verts) r2 = std::max(r2, length_squared(m_.positions[v] - centre));
        const size_t count = a.tris.size() + (b ? b->tris.size() : 0);
        const Vec3f sum = b ? a.normal_sum + b->normal_sum : a.normal_sum;
        const float len = length(sum);
        const Vec3f n_avg = len > 1e-3f * static_cast<float>(count)  // eq. 3.2, or the fallback
                                ? sum * (1.0f / len)
                                : m_.normal[b ? larger_triangle(m_, a.largest, b->largest) : a.largest];
        double area_p = projected_area(a, n_avg);  // eq. 3.3
        if (b) area_p = projected_area(*b, n_avg, area_p);
        const double area_c = kPi * r2;                           // eq. 3.1
        const double reg = area_c > 0.0 ? area_p / area_c : 0.0;  // eq. 3.4
        const double verts = static_cast<double>(b ? union_count(a.verts, b->verts) : a.verts.size());
        const double reg_bound = verts / o_.max_count;            // eq. 3.5
        const double sphere_area = 4.0 * kPi * r2;
        const double size_bound = m_.avg_sphere_area > 0.0      // eq. 3.7
                                      ? std::max(1.0, sphere_area / (o_.max_size * m_.avg_sphere_area))
                                      : 1.0;
        return reg - size_bound * reg_bound;                    // eq. 3.8
    }

private:
    // Continues the sum in the same order as one loop over a's then b's
    // triangles would: the result is bit-identical.
    [[nodiscard]] double projected_area(const Cluster& c, Vec3f n_avg, double sum = 0.0) const {
        for (uint32_t t : c.tris) {
            const Vec4f& na = m_.normal_area[t];
            sum += na.w * std::fabs(dot(n_avg, Vec3f(na.x, na.y, na.z)));
        }
        return sum;
    }

    const MeshData& m_;
    ClusterOptions o_;
};

// a absorbs b (triangles, vertices, box, sums); adjacency is the caller's.
void absorb(const MeshData& m, Cluster& a, Cluster& b) {
    a.tris.insert(a.tris.end(), b.tris.begin(), b.tris.end());
    std::vector<uint32_t> verts;
    verts.reserve(a.verts.size() + b.verts.size());
    std::set_union(a.verts.begin(), a.verts.end(), b.verts.begin(), b.verts.end(), std::back_inserter(verts));
    a.verts = std::move(verts);
    a.box.extend(b.box);
    a.normal_sum = a.normal_sum + b.normal_sum;
    a.area += b.area;
    a.largest = larger_triangle(m, a.largest, b.largest);
    ++a.version;
}

// ---- Iterative merging.

class Merger {
public:
    Merger(const MeshData& m, const DualGraph& g, const Scorer& s) : m_(m), g_(g), s_(s) {}

    // Clusters (sorted triangle lists, ordered by first triangle) after
    // contracting edges until none is mergeable or `target` clusters remain.
    std::vector<std::vector<uint32_t>> run(size_t target) {
        const uint32_t n = static_cast<uint32_t>(m_.area.size());
        clusters_.resize(n);
        parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t t = lo; t < hi; ++t) {
                make_singleton(m_, t, clusters_[t]);
                const auto nb = g_.neighbours(t);
                clusters_[t].adj.assign(nb.begin(), nb.end());
            }
        });
        stamp_.assign(n, 0u);
        push_initial_edges(n);
        size_t alive = n;
        while (alive > target && !queue_.empty()) {
            const MergeQueue::Entry e = queue_.pop();
            if (stamp_[e.a] != e.version_a || stamp_[e.b] != e.version_b) continue;
            contract(e.a, e.b);
            --alive;
        }
        std::vector<std::vector<uint32_t>> out;
        out.reserve(alive);
        for (Cluster& c : clusters_) {
            if (!c.alive) continue;
            std::sort(c.tris.begin(), c.tris.end());
            out.push_back(std::move(c.tris));
        }
        return out;
    }

private:
    // Edge keys in parallel (one slot per CSR entry), pushed in CSR order.
    void push_initial_edges(uint32_t n) {
        std::vector<float> keys(g_.adjacent.size(), kNoMerge);
        parallel::for_range(0u, n, 1024u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t t = lo; t < hi; ++t) {
                for (uint32_t k = g_.first[t]; k < g_.first[t + 1]; ++k) {
                    if (g_.adjacent[k] > t) keys[k] = s_.score(clusters_[t], &clusters_[g_.adjacent[k]]);
                }
            }
        });
        for (uint32_t t = 0; t < n; ++t) {
            for (uint32_t k = g_.first[t]; k < g_.first[t + 1]; ++k) {
                if (s_.mergeable(keys[k])) queue_.push({keys[k], t, g_.adjacent[k], 0, 0});
            }
        }
    }

    static void replace_neighbour(std::vector<uint32_t>& adj, uint32_t from, uint32_t to) {
        auto it = std::lower_bound(adj.begin(), adj.end(), from);
        if (it != adj.end() && *it == from) adj.erase(it);
        it = std::lower_bound(adj.begin(), adj.end(), to);
        if (it == adj.end() || *it != to) adj.insert(it, to);
    }

    void contract(uint32_t a, uint32_t b) {
        Cluster& ca = clusters_[a];
        Cluster& cb = clusters_[b];
        absorb(m_, ca, cb);
        cb.alive = false;
        stamp_[a] = ca.version;
        stamp_[b] = kDead;
        std::vector<uint32_t> adj;
        adj.reserve(ca.adj.size() + cb.adj.size());
        std::set_union(ca.adj.begin(), ca.adj.end(), cb.adj.begin(), cb.adj.end(), std::back_inserter(adj));
        adj.erase(std::remove_if(adj.begin(), adj.end(), [&](uint32_t c) { return c == a || c == b; }), adj.end());
        for (uint32_t c : cb.adj) {
            if (c != a) replace_neighbour(clusters_[c].adj, b, a);
        }
        ca.adj = std::move(adj);
        cb = Cluster{};
        cb.alive = false;
        for (uint32_t c : ca.adj) {
            const float key = s_.score(ca, &clusters_[c]);
            if (!s_.mergeable(key)) continue;
            const uint32_t lo = std::min(a, c), hi = std::max(a, c);
            queue_.push({key, lo, hi, clusters_[lo].version, clusters_[hi].version});
        }
    }

    const MeshData& m_;
    const DualGraph& g_;
    const Scorer& s_;
    std::vector<Cluster> clusters_;
    // Per cluster its version, kDead once absorbed: stale queue entries are
    // found without touching the (large, scattered) clusters.
    static constexpr uint32_t kDead = std::numeric_limits<uint32_t>::max();
    std::vector<uint32_t> stamp_;
    MergeQueue queue_;
};

// ---- Iterative growing.

std::vector<uint32_t> random_order(uint32_t n, uint64_t seed) {
    std::vector<uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::mt19937_64 rng(seed);
    for (uint32_t i = n; i > 1; --i) std::swap(order[i - 1], order[rng() % i]);  // Fisher-Yates
    return order;
}

// Clusters grown from random start triangles; `size_limit` caps their triangles.
std::vector<std::vector<uint32_t>> grow(const MeshData& m, const DualGraph& g, const Scorer& s,
                                        const ClusterOptions& o, uint32_t size_limit) {
    const uint32_t n = static_cast<uint32_t>(m.area.size());
    std::vector<uint8_t> assigned(n, 0);
    std::vector<uint32_t> frontier_mark(n, 0);  // cluster number + 1 when in that cluster's frontier
    std::vector<std::vector<uint32_t>> out;
    Cluster cluster, candidate;
    std::vector<uint32_t> frontier;
    for (uint32_t start : random_order(n, o.seed)) {
        if (assigned[start]) continue;
        const uint32_t mark = static_cast<uint32_t>(out.size()) + 1;
        make_singleton(m, start, cluster);
        assigned[start] = 1;
        frontier.clear();
        auto add_neighbours = [&](uint32_t t) {
            for (uint32_t u : g.neighbours(t)) {
                if (!assigned[u] && frontier_mark[u] != mark) frontier_mark[u] = mark, frontier.push_back(u);
            }
        };
        add_neighbours(start);
        while (cluster.tris.size() < size_limit && !frontier.empty()) {
            size_t best = 0;
            float best_key = kNoMerge;
            for (size_t i = 0; i < frontier.size(); ++i) {
                make_singleton(m, frontier[i], candidate);
                const float key = s.score(cluster, &candidate);
                if (key > best_key || (key == best_key && frontier[i] < frontier[best])) best = i, best_key = key;
            }
            if (!s.mergeable(best_key)) break;
            const uint32_t t = frontier[best];
            frontier[best] = frontier.back();
            frontier.pop_back();
            make_singleton(m, t, candidate);
            absorb(m, cluster, candidate);
            assigned[t] = 1;
            add_neighbours(t);
        }
        std::sort(cluster.tris.begin(), cluster.tris.end());
        out.push_back(cluster.tris);
    }
    std::sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a[0] < b[0]; });
    return out;
}

std::vector<std::vector<uint32_t>> generate(const MeshData& m, const DualGraph& g, const ClusterOptions& o,
                                            size_t target, uint32_t size_limit) {
    const Scorer scorer(m, o);
    if (o.generation == ClusterGeneration::Grow) return grow(m, g, scorer, o, size_limit);
    return Merger(m, g, scorer).run(target);
}

ClusterPartition to_partition(const MeshData& m, const std::vector<std::vector<uint32_t>>& clusters) {
    ClusterPartition p;
    p.first.reserve(clusters.size() + 1);
    p.vertex_first.reserve(clusters.size() + 1);
    p.triangles.reserve(m.area.size());
    std::vector<uint32_t> seen(m.positions.size(), 0);  // cluster number + 1 that listed the vertex
    for (size_t c = 0; c < clusters.size(); ++c) {
        for (uint32_t t : clusters[c]) {
            p.triangles.push_back(t);
            for (int k = 0; k < 3; ++k) {
                const uint32_t v = m.indices[3 * size_t{t} + k];
                if (seen[v] == c + 1) continue;
                seen[v] = static_cast<uint32_t>(c + 1);
                p.vertex_refs.push_back(3 * uint64_t{t} + k);
            }
        }
        p.first.push_back(static_cast<uint32_t>(p.triangles.size()));
        p.vertex_first.push_back(static_cast<uint32_t>(p.vertex_refs.size()));
    }
    return p;
}

// Gathers t's dual neighbours into `out` (sorted, unique, without t).
void gather_neighbours(std::span<const uint32_t> indices, const std::vector<uint32_t>& vfirst,
                       const std::vector<uint32_t>& vtris, uint32_t t, std::vector<uint32_t>& out) {
    out.clear();
    for (int k = 0; k < 3; ++k) {
        const uint32_t v = indices[3 * size_t{t} + k];
        const uint32_t* begin = vtris.data() + vfirst[v];
        const uint32_t* end = vtris.data() + vfirst[v + 1];
        if (end - begin <= static_cast<ptrdiff_t>(DualGraph::kMaxFan)) {
            out.insert(out.end(), begin, end);
            continue;
        }
        const uint32_t* at = std::lower_bound(begin, end, t);  // t is listed: link to its chain neighbours
        if (at != begin) out.push_back(at[-1]);
        if (at + 1 < end) out.push_back(at[1]);
    }
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    out.erase(std::remove(out.begin(), out.end(), t), out.end());
}

}  // namespace

// ---- MergeQueue.

MergeQueue::MergeQueue() : buckets_(kBuckets) {}

int MergeQueue::bucket_of(float key) {
    const float x = (key + 2.0f) * (static_cast<float>(kBuckets) / 4.0f);
    if (!(x > 0.0f)) return 0;
    return x >= static_cast<float>(kBuckets - 1) ? kBuckets - 1 : static_cast<int>(x);
}

namespace {
// Heap order: the largest key on top, then the smallest (a, b).
bool lower_priority(const MergeQueue::Entry& x, const MergeQueue::Entry& y) {
    if (x.key != y.key) return x.key < y.key;
    return x.a != y.a ? x.a > y.a : x.b > y.b;
}
}  // namespace

void MergeQueue::push(const Entry& entry) {
    if (std::isnan(entry.key)) return;
    const int b = bucket_of(entry.key);
    buckets_[b].push_back(entry);
    std::push_heap(buckets_[b].begin(), buckets_[b].end(), lower_priority);
    top_ = std::max(top_, b);
    ++size_;
}

MergeQueue::Entry MergeQueue::pop() {
    while (buckets_[top_].empty()) --top_;
    std::vector<Entry>& bucket = buckets_[top_];
    std::pop_heap(bucket.begin(), bucket.end(), lower_priority);
    const Entry e = bucket.back();
    bucket.pop_back();
    --size_;
    return e;
}

// ---- Public functions.

DualGraph build_dual_graph(std::span<const uint32_t> indices, size_t vertex_count) {
    const uint32_t n = static_cast<uint32_t>(indices.size() / 3);
    std::vector<uint32_t> vfirst(vertex_count + 1, 0), vtris(size_t{n} * 3);
    for (uint32_t i : indices) {
        if (i >= vertex_count) throw Error("clusters: vertex index " + std::to_string(i) + " out of range");
        ++vfirst[i + 1];
    }
    std::partial_sum(vfirst.begin(), vfirst.end(), vfirst.begin());
    std::vector<uint32_t> cursor(vfirst.begin(), vfirst.end() - 1);
    for (uint32_t t = 0; t < n; ++t) {
        for (int k = 0; k < 3; ++k) {
            const uint32_t v = indices[3 * size_t{t} + k];
            if (k > 0 && indices[3 * size_t{t} + k - 1] == v) continue;  // (a, a, b): list t once per vertex
            if (k == 2 && indices[3 * size_t{t}] == v) continue;
            vtris[cursor[v]++] = t;
        }
    }
    // Repeated corners leave unused slots at the end of a vertex's range: compact.
    size_t w = 0;
    for (size_t v = 0; v < vertex_count; ++v) {
        const uint32_t begin = vfirst[v], end = cursor[v];
        vfirst[v] = static_cast<uint32_t>(w);
        for (uint32_t i = begin; i < end; ++i) vtris[w++] = vtris[i];
    }
    vfirst[vertex_count] = static_cast<uint32_t>(w);
    DualGraph g;
    g.first.assign(size_t{n} + 1, 0);
    parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
        std::vector<uint32_t> scratch;
        for (uint32_t t = lo; t < hi; ++t) {
            gather_neighbours(indices, vfirst, vtris, t, scratch);
            g.first[t + 1] = static_cast<uint32_t>(scratch.size());
        }
    });
    std::partial_sum(g.first.begin(), g.first.end(), g.first.begin());
    g.adjacent.resize(g.first[n]);
    parallel::for_range(0u, n, 4096u, [&](uint32_t lo, uint32_t hi) {
        std::vector<uint32_t> scratch;
        for (uint32_t t = lo; t < hi; ++t) {
            gather_neighbours(indices, vfirst, vtris, t, scratch);
            std::copy(scratch.begin(), scratch.end(), g.adjacent.begin() + g.first[t]);
        }
    });
    return g;
}

void validate_cluster_options(const ClusterOptions& o) {
    if (o.max_count < 1) throw Error("cluster options: max_count must be at least 1, got " + std::to_string(o.max_count));
    if (!(o.max_size > 0.0f) || !std::isfinite(o.max_size)) {
        throw Error("cluster options: max_size must be positive and finite, got " + std::to_string(o.max_size));
    }
    if (o.leaf_triangles < 1 || o.leaf_triangles > static_cast<int>(kMaxClusterTriangles)) {
        throw Error("cluster options: leaf_triangles must be in [1, 64], got " + std::to_string(o.leaf_triangles));
    }
}

namespace {
Cluster cluster_of(const MeshData& m, std::span<const uint32_t> triangles) {
    Cluster c, one;
    for (size_t i = 0; i < triangles.size(); ++i) {
        if (i == 0) {
            make_singleton(m, triangles[0], c);
            continue;
        }
        make_singleton(m, triangles[i], one);
        absorb(m, c, one);
    }
    return c;
}
}  // namespace

double cluster_acc(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                   std::span<const uint32_t> triangles, const ClusterOptions& options) {
    if (triangles.empty()) return 0.0;
    const MeshData m = mesh_data(positions, indices);
    return Scorer(m, options).acc(cluster_of(m, triangles), nullptr);
}

double cluster_naive(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                     std::span<const uint32_t> triangles) {
    if (triangles.empty()) return 0.0;
    const MeshData m = mesh_data(positions, indices);
    return Scorer(m, ClusterOptions{}).naive(cluster_of(m, triangles), nullptr);
}

ClusterPartition cluster_mesh(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                              const ClusterOptions& options) {
    validate_cluster_options(options);
    if (indices.size() % 3 != 0) throw Error("clusters: index count is not a multiple of 3");
    if (indices.size() / 3 >= std::numeric_limits<uint32_t>::max()) throw Error("clusters: too many triangles");
    const MeshData m = mesh_data(positions, indices);
    const DualGraph g = build_dual_graph(indices, positions.size());
    const uint32_t n = static_cast<uint32_t>(m.area.size());
    if (options.heuristic == ClusterHeuristic::Acc) return to_partition(m, generate(m, g, options, 0, kMaxClusterTriangles));
    // Naive stops where Acc does (the text's fair comparison).
    ClusterOptions acc = options;
    acc.heuristic = ClusterHeuristic::Acc;
    const size_t target = generate(m, g, acc, 0, kMaxClusterTriangles).size();
    const uint32_t mean_size = target ? static_cast<uint32_t>((n + target / 2) / target) : 1;
    return to_partition(m, generate(m, g, options, target, std::clamp(mean_size, 1u, kMaxClusterTriangles)));
}

ClusterPartition cluster_scene(const Scene& scene, const SceneGeometry& geometry, const ClusterOptions& options) {
    validate_cluster_options(options);
    if (geometry.instance_first_triangle.size() != scene.instances.size() + 1) {
        throw Error("clusters: the geometry was not built from this scene");
    }
    std::vector<uint32_t> meshes;
    for (const Instance& inst : scene.instances) meshes.push_back(inst.mesh);
    std::sort(meshes.begin(), meshes.end());
    meshes.erase(std::unique(meshes.begin(), meshes.end()), meshes.end());
    std::vector<ClusterPartition> per_mesh(scene.meshes.size());
    parallel::for_range(size_t{0}, meshes.size(), size_t{1}, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const Mesh& mesh = scene.meshes[meshes[i]];
            per_mesh[meshes[i]] = cluster_mesh(mesh.positions, mesh.indices, options);
        }
    });
    ClusterPartition out;
    for (size_t i = 0; i < scene.instances.size(); ++i) {
        const ClusterPartition& p = per_mesh[scene.instances[i].mesh];
        const uint32_t base = geometry.instance_first_triangle[i];
        if (geometry.instance_first_triangle[i + 1] - base != p.triangles.size()) {
            throw Error("clusters: instance " + std::to_string(i) + " does not match its mesh's triangle count");
        }
        for (size_t c = 0; c < p.size(); ++c) {
            for (uint32_t t : p.cluster(c)) out.triangles.push_back(base + t);
            for (uint64_t r : p.vertices(c)) out.vertex_refs.push_back(r + 3 * uint64_t{base});
            out.first.push_back(static_cast<uint32_t>(out.triangles.size()));
            out.vertex_first.push_back(static_cast<uint32_t>(out.vertex_refs.size()));
        }
    }
    return out;
}

}  // namespace rf
