// BVH builds over precomputed clusters of connected triangles (Garanzha
// 2014 ch. 3): any BVH builder runs over the clusters' boxes, and the
// canonical BVH's leaves list the clusters' triangles. The updater of
// UpdateMethod::Clusters (make_cluster_updater, accel/update/bvh_updater.h)
// rebuilds it every frame over the frame-1 clusters.
#pragma once

#include <span>
#include <vector>

#include "accel/bvh/builders/cluster_generation.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf {

// The options the build over cluster boxes runs with: `build`'s builder
// and options, one cluster per leaf (the leaves are merged by triangle
// count afterwards), spatial-split builders replaced by their object-split
// counterparts (SBVH -> sweep SAH, GridBvhSplit -> GridBvh: a box has no
// triangle to clip).
BuildOptions cluster_box_build_options(const BuildOptions& build);

// The canonical BVH over `triangles` whose inner levels are built by
// box_options' builder over the boxes of `clusters` (recomputed from the
// triangles' current positions): a subtree whose clusters hold at most
// `leaf_triangles` triangles in total becomes one leaf listing them
// (cluster by cluster); a cluster is never split. Runs on the calling
// thread's arena; deterministic when the builder is.
//
// With `subtrees` (ClusterOptions::cluster_subtrees; refitted to the same
// triangles), a cluster's box is its subtree's root box, the recursion goes
// down to single clusters (subtrees of at most `leaf_triangles` triangles
// in total become one leaf) and each cluster's subtree is grafted under its
// leaf, unless that would pass kBvhMaxDepth (then the cluster is one leaf).
struct ClusterSubtrees;
Bvh build_cluster_bvh(std::span<const Triangle> triangles, const ClusterPartition& clusters,
                      const BuildOptions& box_options, int leaf_triangles, const ClusterSubtrees* subtrees = nullptr);

// Per-cluster BVHs over the clusters' own triangles: cluster c's nodes are
// nodes[node_first[c], node_first[c+1]) in depth-first order, an inner
// node's first child relative to node_first[c], a leaf's first triangle
// relative to the cluster's first slot in ClusterPartition::triangles.
struct ClusterSubtrees {
    std::vector<BvhNode> nodes;
    std::vector<uint32_t> node_first{0};
    std::vector<uint8_t> depth;  // per cluster: inner nodes on its longest root-to-leaf path
};
// Builds every cluster's subtree with the binned SAH (build's leaf size and
// costs) and reorders each cluster's triangles into its leaves' order.
ClusterSubtrees build_cluster_subtrees(std::span<const Triangle> triangles, ClusterPartition& clusters,
                                       const BuildOptions& build);
// Recomputes every subtree's boxes, bottom-up, from the triangles.
void refit_cluster_subtrees(std::span<const Triangle> triangles, const ClusterPartition& clusters,
                            ClusterSubtrees& subtrees);

}  // namespace rf
