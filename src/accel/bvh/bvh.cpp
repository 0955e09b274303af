// Quality metrics of the canonical BVH.
#include "rayforge/accel/bvh/bvh.h"

#include <utility>
#include <vector>

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

double Bvh::quality_cost(double node_cost) const {
    if (nodes.empty()) return 0.0;
    // Post-order over an explicit stack (no assumption about node order):
    // a node is finished once both children's costs are known.
    std::vector<double> cost(nodes.size(), 0.0);
    std::vector<std::pair<uint32_t, bool>> stack{{0u, false}};
    while (!stack.empty()) {
        const auto [index, children_done] = stack.back();
        stack.pop_back();
        const BvhNode& node = nodes[index];
        if (node.is_leaf()) {
            cost[index] = double(node.count);
        } else if (!children_done) {
            stack.push_back({index, true});
            stack.push_back({node.first, false});
            stack.push_back({node.first + 1, false});
        } else {
            const double area = node.bounds.surface_area();
            double children = 0.0;
            for (uint32_t c = node.first; c < node.first + 2; ++c) {
                // A flat or point-like node: a ray reaching it reaches its children.
                const double ratio = area > 0.0 ? double(nodes[c].bounds.surface_area()) / area : 1.0;
                children += cost[c] * ratio;
            }
            cost[index] = node_cost + children;
        }
    }
    return cost[0];
}

}  // namespace rf
