// Cluster-based BVH builds (Garanzha 2014, ch. 3; Garanzha 2009, "The Use
// of Precomputed Triangle Clusters for Accelerated Ray Tracing in Dynamic
// Scenes", EGSR 2009 / CGF 28(4)).
//
// Clusters of connected triangles are computed once, from the first frame's
// positions (cluster_generation.cpp: Acc(k) or Naive(k), merging or
// growing; its header comment lists how the text's gaps are resolved: the
// box-centred bounding sphere, 4096 queue buckets over [-2, 2]). Every
// frame, each cluster's box is recomputed from its distinct vertices, any
// BVH builder (BuildOptions::builder; the text names Wald 2007's binned SAH)
// runs over the boxes, and the result is turned into the canonical BVH over
// triangles: the recursion's stop "a node's clusters hold at most L = 32
// triangles" is applied to the builder's tree of one-cluster leaves, and a
// leaf lists its clusters' triangles. Clusters hold at most 64 triangles
// (the BVH8 collapse's largest leaf), so no leaf needs splitting; a builder
// that still puts several clusters of more than 64 triangles into one leaf
// gets that leaf halved into a small subtree.
//
// Data layout: a cluster is a range of a triangle list and a range of
// (triangle, corner) references, one per distinct vertex (the vertex list of
// the text, addressed in the flat world-space triangles so the updater needs
// nothing but them). The builder sees each cluster as a degenerate triangle
// (box lo, box hi, box centre): its bounds are the box and its centroid the
// box's centre, which is all a builder without spatial splits looks at.
//
// Parallelism: boxes in a parallel loop; the builder's own parallelism;
// the canonical tree's nodes are emitted by one depth-first pass (a
// cluster-level tree, small), its leaves' triangles copied in parallel.
//
// Determinism: the output depends only on the clusters, the positions and
// the builder's output, which is thread-count independent for every builder.
#include "accel/bvh/builders/clusters.h"

#include <algorithm>
#include <memory>
#include <optional>
#include <string>

#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"
#include "core/parallel.h"
#include "core/assert.h"
#include "rayforge/core/error.h"

namespace rf {
namespace {

// Box3f::extend without the libm calls fminf/fmaxf (not inlined): refits
// and cluster boxes spend most of their time here.
inline void grow(Box3f& b, Vec3f p) {
    b.lo = Vec3f(p.x < b.lo.x ? p.x : b.lo.x, p.y < b.lo.y ? p.y : b.lo.y, p.z < b.lo.z ? p.z : b.lo.z);
    b.hi = Vec3f(p.x > b.hi.x ? p.x : b.hi.x, p.y > b.hi.y ? p.y : b.hi.y, p.z > b.hi.z ? p.z : b.hi.z);
}

inline Vec3f corner_of(const Triangle& t, uint64_t corner) { return corner == 0 ? t.v0 : corner == 1 ? t.v1 : t.v2; }

// Each cluster as the degenerate triangle (lo, hi, centre) of its box.
std::vector<Triangle> cluster_proxies(std::span<const Triangle> triangles, const ClusterPartition& clusters) {
    std::vector<Triangle> proxies(clusters.size());
    parallel::for_range(size_t{0}, clusters.size(), size_t{1024}, [&](size_t lo, size_t hi) {
        for (size_t c = lo; c < hi; ++c) {
            Box3f box;
            for (uint64_t ref : clusters.vertices(c)) grow(box, corner_of(triangles[ref / 3], ref % 3));
            proxies[c] = Triangle{box.lo, box.hi, box.center()};
        }
    });
    return proxies;
}

// Each cluster as the degenerate triangle of its subtree's root box.
std::vector<Triangle> subtree_proxies(const ClusterSubtrees& subtrees) {
    std::vector<Triangle> proxies(subtrees.depth.size());
    for (size_t c = 0; c < proxies.size(); ++c) {
        const Box3f& box = subtrees.nodes[subtrees.node_first[c]].bounds;
        proxies[c] = Triangle{box.lo, box.hi, box.center()};
    }
    return proxies;
}

// Emits the canonical BVH from the tree over clusters.
class Emitter {
public:
    Emitter(const Bvh& src, const ClusterPartition& clusters, std::span<const Triangle> proxies, uint32_t leaf,
            const ClusterSubtrees* subtrees)
        : src_(src), clusters_(clusters), proxies_(proxies), leaf_(leaf), sub_(subtrees), tris_(src.nodes.size()) {}

    Bvh run(size_t triangle_count) {
        count(0);
        out_.nodes.reserve(src_.nodes.size() + (sub_ ? sub_->nodes.size() : 0));
        out_.nodes.emplace_back();
        emit(0, 0, 0);
        RF_ASSERT(cursor_ == triangle_count, "every triangle in one leaf");
        out_.prim_indices.resize(triangle_count);
        parallel::for_range(size_t{0}, jobs_.size(), size_t{64}, [&](size_t lo, size_t hi) {
            for (size_t j = lo; j < hi; ++j) fill(jobs_[j]);
        });
        parallel::for_range(size_t{0}, grafts_.size(), size_t{256}, [&](size_t lo, size_t hi) {
            for (size_t j = lo; j < hi; ++j) copy_graft(grafts_[j]);
        });
        return std::move(out_);
    }

private:
    // Triangles of the output copied from the source's clusters: those of a
    // source subtree, or of a range of a source leaf's slots.
    struct Job {
        uint32_t first;
        uint32_t node;
        uint32_t slot_begin, slot_end;  // equal: the whole subtree of `node`
    };

    // A cluster's subtree copied under output node `root`: its other nodes
    // keep their depth-first order in nodes [block, block + count - 1).
    struct Graft {
        uint32_t cluster, root, block, first_slot;
    };

    uint32_t cluster_size(uint32_t c) const { return clusters_.first[c + 1] - clusters_.first[c]; }

    uint32_t count(uint32_t n) {
        const BvhNode& node = src_.nodes[n];
        uint32_t total = 0;
        if (node.is_leaf()) {
            for (uint32_t s = node.first; s < node.first + node.count; ++s) total += cluster_size(src_.prim_indices[s]);
        } else {
            total = count(node.first) + count(node.first + 1);
        }
        return tris_[n] = total;
    }

    void make_leaf(uint32_t o, const Box3f& bounds, uint32_t tris, const Job& job) {
        out_.nodes[o] = BvhNode{bounds, static_cast<uint32_t>(cursor_), tris};
        jobs_.push_back(Job{static_cast<uint32_t>(cursor_), job.node, job.slot_begin, job.slot_end});
        cursor_ += tris;
    }

    uint32_t new_pair() {
        const uint32_t c = static_cast<uint32_t>(out_.nodes.size());
        out_.nodes.emplace_back();
        out_.nodes.emplace_back();
        return c;
    }

    void emit(uint32_t n, uint32_t o, int depth) {
        const BvhNode& node = src_.nodes[n];
        const bool split_leaf = sub_ ? node.count > 1 : node.count > 1 && tris_[n] > kMaxClusterTriangles;
        if (node.is_leaf() && split_leaf && tris_[n] > leaf_) {
            emit_slots(n, node.first, node.first + node.count, o, depth);
        } else if (tris_[n] <= leaf_ || (node.is_leaf() && !sub_)) {
            make_leaf(o, node.bounds, tris_[n], Job{0, n, 0, 0});
        } else if (node.is_leaf()) {
            graft(n, node.first, o, depth);
        } else {
            const uint32_t c = new_pair();
            out_.nodes[o] = BvhNode{node.bounds, c, 0};
            emit(node.first, c, depth + 1);
            emit(node.first + 1, c + 1, depth + 1);
        }
    }

    // A source leaf's slots [begin, end) halved until they fit a leaf (or,
    // with subtrees, down to single clusters).
    void emit_slots(uint32_t n, uint32_t begin, uint32_t end, uint32_t o, int depth) {
        Box3f bounds;
        uint32_t tris = 0;
        for (uint32_t s = begin; s < end; ++s) {
            const uint32_t c = src_.prim_indices[s];
            bounds.extend(proxies_[c].bounds());
            tris += cluster_size(c);
        }
        if (tris <= leaf_ || (end - begin == 1 && !sub_)) {
            make_leaf(o, bounds, tris, Job{0, n, begin, end});
        } else if (end - begin == 1) {
            graft(n, begin, o, depth);
        } else {
            const uint32_t mid = begin + (end - begin) / 2;
            const uint32_t c = new_pair();
            out_.nodes[o] = BvhNode{bounds, c, 0};
            emit_slots(n, begin, mid, c, depth + 1);
            emit_slots(n, mid, end, c + 1, depth + 1);
        }
    }

    // The subtree of the cluster in source slot `slot` at output node o.
    void graft(uint32_t n, uint32_t slot, uint32_t o, int depth) {
        const uint32_t c = src_.prim_indices[slot];
        const uint32_t size = cluster_size(c);
        if (depth + sub_->depth[c] > kBvhMaxDepth) {
            make_leaf(o, proxies_[c].bounds(), size, Job{0, n, slot, slot + 1});
            return;
        }
        jobs_.push_back(Job{static_cast<uint32_t>(cursor_), n, slot, slot + 1});
        const uint32_t block = static_cast<uint32_t>(out_.nodes.size());
        out_.nodes.resize(out_.nodes.size() + (sub_->node_first[c + 1] - sub_->node_first[c] - 1));
        grafts_.push_back(Graft{c, o, block, static_cast<uint32_t>(cursor_)});
        cursor_ += size;
    }
    // Node i of the subtree (0: its root) with its references made absolute;
    // sibling pairs stay adjacent, so a pair at i maps to block + i - 1.
    void copy_graft(const Graft& g) {
        const uint32_t base = sub_->node_first[g.cluster], end = sub_->node_first[g.cluster + 1];
        for (uint32_t i = base; i < end; ++i) {
            const BvhNode& node = sub_->nodes[i];
            const BvhNode copy = node.is_leaf() ? BvhNode{node.bounds, g.first_slot + node.first, node.count}
                                                : BvhNode{node.bounds, g.block + node.first - 1, 0};
            out_.nodes[i == base ? g.root : g.block + (i - base) - 1] = copy;
        }
    }

    uint32_t copy_slots(uint32_t begin, uint32_t end, uint32_t at) {
        for (uint32_t s = begin; s < end; ++s) {
            for (uint32_t t : clusters_.cluster(src_.prim_indices[s])) out_.prim_indices[at++] = t;
        }
        return at;
    }
    uint32_t copy_subtree(uint32_t n, uint32_t at) {
        const BvhNode& node = src_.nodes[n];
        if (node.is_leaf()) return copy_slots(node.first, node.first + node.count, at);
        return copy_subtree(node.first + 1, copy_subtree(node.first, at));
    }
    void fill(const Job& job) {
        if (job.slot_begin != job.slot_end) {
            copy_slots(job.slot_begin, job.slot_end, job.first);
        } else {
            copy_subtree(job.node, job.first);
        }
    }

    const Bvh& src_;
    const ClusterPartition& clusters_;
    std::span<const Triangle> proxies_;
    uint32_t leaf_;
    const ClusterSubtrees* sub_;
    std::vector<uint32_t> tris_;  // per source node: triangles of its clusters
    std::vector<Job> jobs_;
    std::vector<Graft> grafts_;
    Bvh out_;
    size_t cursor_ = 0;
};

int subtree_depth(const Bvh& bvh, uint32_t n) {
    const BvhNode& node = bvh.nodes[n];
    return node.is_leaf() ? 0 : 1 + std::max(subtree_depth(bvh, node.first), subtree_depth(bvh, node.first + 1));
}

}  // namespace

BuildOptions cluster_box_build_options(const BuildOptions& build) {
    BuildOptions o = build;
    o.max_leaf_size = 1;
    if (o.builder == Builder::Sbvh) o.builder = Builder::SweepSah;
    if (o.builder == Builder::GridBvhSplit) o.builder = Builder::GridBvh;
    return o;
}

Bvh build_cluster_bvh(std::span<const Triangle> triangles, const ClusterPartition& clusters,
                      const BuildOptions& box_options, int leaf_triangles, const ClusterSubtrees* subtrees) {
    if (clusters.size() == 0) return Bvh{};
    const std::vector<Triangle> proxies = subtrees ? subtree_proxies(*subtrees) : cluster_proxies(triangles, clusters);
    const Bvh over_boxes = build_bvh_on_cpu(proxies, box_options);
    return Emitter(over_boxes, clusters, proxies, static_cast<uint32_t>(leaf_triangles), subtrees)
        .run(clusters.triangles.size());
}

ClusterSubtrees build_cluster_subtrees(std::span<const Triangle> triangles, ClusterPartition& clusters,
                                       const BuildOptions& build) {
    const size_t n = clusters.size();
    std::vector<Bvh> trees(n);
    ClusterSubtrees out;
    out.depth.resize(n);
    BvhBuildConfig config = bvh_build_config(build);
    parallel::for_range(size_t{0}, n, size_t{64}, [&](size_t lo, size_t hi) {
        std::vector<Triangle> local;
        std::vector<uint32_t> order;
        for (size_t c = lo; c < hi; ++c) {
            const std::span<const uint32_t> tris = clusters.cluster(c);
            local.clear();
            for (uint32_t t : tris) local.push_back(triangles[t]);
            trees[c] = build_binned_sah(local, config, build.binned);
            order.clear();
            for (uint32_t p : trees[c].prim_indices) order.push_back(tris[p]);  // leaves' order
            std::copy(order.begin(), order.end(), clusters.triangles.begin() + clusters.first[c]);
            out.depth[c] = static_cast<uint8_t>(std::min(subtree_depth(trees[c], 0), 255));
        }
    });
    for (size_t c = 0; c < n; ++c) {
        out.nodes.insert(out.nodes.end(), trees[c].nodes.begin(), trees[c].nodes.end());
        out.node_first.push_back(static_cast<uint32_t>(out.nodes.size()));
    }
    return out;
}

void refit_cluster_subtrees(std::span<const Triangle> triangles, const ClusterPartition& clusters,
                            ClusterSubtrees& subtrees) {
    parallel::for_range(size_t{0}, clusters.size(), size_t{256}, [&](size_t lo, size_t hi) {
        for (size_t c = lo; c < hi; ++c) {
            const uint32_t base = subtrees.node_first[c];
            const uint32_t* tris = clusters.triangles.data() + clusters.first[c];
            // Depth-first order: children after their parent, so backwards is bottom-up.
            for (uint32_t i = subtrees.node_first[c + 1]; i-- > base;) {
                BvhNode& node = subtrees.nodes[i];
                Box3f box;
                if (node.is_leaf()) {
                    for (uint32_t k = node.first; k < node.first + node.count; ++k) {
                        const Triangle& t = triangles[tris[k]];
                        grow(box, t.v0), grow(box, t.v1), grow(box, t.v2);
                    }
                } else {
                    box = subtrees.nodes[base + node.first].bounds;
                    const Box3f& other = subtrees.nodes[base + node.first + 1].bounds;
                    grow(box, other.lo), grow(box, other.hi);
                }
                node.bounds = box;
            }
        }
    });
}

}  // namespace rf
