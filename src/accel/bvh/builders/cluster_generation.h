// Clusters of connected triangles for the cluster-based BVH builds of
// Garanzha 2014 ch. 3 (EGSR 2009): the dual graph, the Acc(k) and Naive(k)
// heuristics, the bucketed merge queue, and generation by iterative merging
// or growing. clusters.h builds BVHs over the clusters' boxes.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "rayforge/accel/dynamic_accel.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// The most triangles a cluster holds: the wide BVH collapse's largest leaf
// (16 packs of 4 triangles), so that every cluster fits one leaf.
inline constexpr uint32_t kMaxClusterTriangles = 64;

// Clusters as compressed lists: cluster c holds triangles[first[c],
// first[c+1]) (ascending) and its distinct vertices, each named by one
// corner that uses it: vertex_refs[vertex_first[c], vertex_first[c+1]),
// triangle * 3 + corner.
struct ClusterPartition {
    std::vector<uint32_t> first{0};
    std::vector<uint32_t> triangles;
    std::vector<uint32_t> vertex_first{0};
    std::vector<uint64_t> vertex_refs;

    [[nodiscard]] size_t size() const { return first.size() - 1; }
    [[nodiscard]] std::span<const uint32_t> cluster(size_t c) const {
        return {triangles.data() + first[c], first[c + 1] - first[c]};
    }
    [[nodiscard]] std::span<const uint64_t> vertices(size_t c) const {
        return {vertex_refs.data() + vertex_first[c], vertex_first[c + 1] - vertex_first[c]};
    }
};

// The dual graph: triangles t and u are adjacent when they share a vertex
// index. Around a vertex used by more than kMaxFan triangles, each of them
// is linked only to its neighbours in index order (a chain), which keeps
// such a fan connected without its quadratic number of edges.
struct DualGraph {
    static constexpr uint32_t kMaxFan = 32;
    std::vector<uint32_t> first;     // per triangle + 1
    std::vector<uint32_t> adjacent;  // sorted per triangle, no self edges

    [[nodiscard]] std::span<const uint32_t> neighbours(uint32_t t) const {
        return {adjacent.data() + first[t], first[t + 1] - first[t]};
    }
};
// Throws rf::Error when an index is not below vertex_count.
DualGraph build_dual_graph(std::span<const uint32_t> indices, size_t vertex_count);

// The priority queue of merging: entries bucketed by key over [-2, 2]
// (kBuckets buckets; keys outside go to the end buckets), each bucket a
// binary heap, so pop() returns exactly the largest key (ties: smallest
// (a, b)) and finds it in O(1) buckets. Stale entries are the caller's to
// skip (versions).
class MergeQueue {
public:
    static constexpr int kBuckets = 4096;
    struct Entry {
        float key;
        uint32_t a, b;            // clusters, a < b
        uint32_t version_a, version_b;
    };
    MergeQueue();
    void push(const Entry& entry);  // NaN keys are dropped
    [[nodiscard]] bool empty() const { return size_ == 0; }
    [[nodiscard]] size_t size() const { return size_; }
    Entry pop();  // not empty()
    static int bucket_of(float key);

private:
    std::vector<std::vector<Entry>> buckets_;
    int top_ = 0;  // no bucket above holds an entry
    size_t size_ = 0;
};

// Throws rf::Error for out-of-range options.
void validate_cluster_options(const ClusterOptions& options);

// Acc(k) (eqs. 3.1-3.8) and Naive(k) of a set of a mesh's triangles (any
// set; the generation only forms connected ones). AvgSA is the mesh's.
double cluster_acc(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                   std::span<const uint32_t> triangles, const ClusterOptions& options);
double cluster_naive(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                     std::span<const uint32_t> triangles);

// One mesh's triangles (local ids) partitioned as options say; clusters
// ordered by their smallest triangle. Deterministic for any thread count.
ClusterPartition cluster_mesh(std::span<const Vec3f> positions, std::span<const uint32_t> indices,
                              const ClusterOptions& options);

// Every instance's triangles (flat ids of `geometry`): each mesh is
// clustered once, on its current positions in object space, and every
// instance of it gets that partition.
ClusterPartition cluster_scene(const Scene& scene, const SceneGeometry& geometry, const ClusterOptions& options);

}  // namespace rf
