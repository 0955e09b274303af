// Quality metrics of the canonical BVH.
#include "rayforge/accel/bvh/bvh.h"

namespace rf {

size_t Bvh::leaf_count() const {
    size_t leaves = 0;
    for (const BvhNode& node : nodes) leaves += node.is_leaf() ? 1 : 0;
    return leaves;
}

double Bvh::sah_cost(float traversal_cost, float intersection_cost) const {
    if (nodes.empty()) return 0.0;
    const double root_area = nodes[0].bounds.surface_area();
    double cost = 0.0;
    for (const BvhNode& node : nodes) {
        // A flat or point-like root makes every ratio 0/0: a ray that reaches
        // the root then reaches every node, so count each with weight 1.
        const double ratio = root_area > 0.0 ? node.bounds.surface_area() / root_area : 1.0;
        cost += node.is_leaf() ? ratio * intersection_cost * node.count : ratio * traversal_cost;
    }
    return cost;
}

}  // namespace rf
