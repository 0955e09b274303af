// Queries on the kd-tree of Zlatuška 2009: leaf walks with cells, depth, and the
// SAH cost (Wald and Havran 2006, eq. 1) the builder minimises greedily.
#include "accel/kdtree/kdtree.h"

#include <algorithm>

namespace rf {
namespace {

// Depth-first walk handing each node its cell and depth.
template <class Visit>
void walk(const KdTree& tree, Visit&& visit) {
    if (tree.nodes.empty()) return;
    struct Item {
        uint32_t node;
        int depth;
        Box3f cell;
    };
    std::vector<Item> stack{{0, 0, tree.bounds}};
    while (!stack.empty()) {
        const Item item = stack.back();
        stack.pop_back();
        const KdNode& node = tree.nodes[item.node];
        visit(item.node, item.depth, item.cell);
        if (node.is_leaf()) continue;
        Box3f below = item.cell, above = item.cell;
        below.hi[node.axis()] = node.split();
        above.lo[node.axis()] = node.split();
        // Above first so that below pops first: depth-first, below before above.
        stack.push_back({node.first_child() + 1, item.depth + 1, above});
        stack.push_back({node.first_child(), item.depth + 1, below});
    }
}

}  // namespace

size_t KdTree::leaf_count() const {
    return static_cast<size_t>(std::count_if(nodes.begin(), nodes.end(), [](const KdNode& n) { return n.is_leaf(); }));
}

size_t KdTree::empty_leaf_count() const {
    return static_cast<size_t>(
        std::count_if(nodes.begin(), nodes.end(), [](const KdNode& n) { return n.is_leaf() && n.prim_count() == 0; }));
}

int KdTree::depth() const {
    int deepest = 0;
    walk(*this, [&](uint32_t, int d, const Box3f&) { deepest = std::max(deepest, d); });
    return deepest;
}

std::vector<KdLeafInfo> KdTree::leaves() const {
    std::vector<KdLeafInfo> out;
    walk(*this, [&](uint32_t node, int d, const Box3f& cell) {
        if (nodes[node].is_leaf()) out.push_back({node, d, cell});
    });
    return out;
}

double KdTree::sah_cost(float traversal_cost, float intersection_cost) const {
    if (nodes.empty()) return 0.0;
    const double root_area = bounds.surface_area();
    if (!(root_area > 0.0)) return static_cast<double>(intersection_cost) * static_cast<double>(prim_indices.size());
    double cost = 0.0;
    walk(*this, [&](uint32_t node, int, const Box3f& cell) {
        const double area = cell.surface_area() / root_area;
        const KdNode& n = nodes[node];
        cost += n.is_leaf() ? area * intersection_cost * n.prim_count() : area * traversal_cost;
    });
    return cost;
}

}  // namespace rf
