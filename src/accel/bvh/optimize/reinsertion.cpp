// Post-build BVH optimizer by reinsertion (Bittner, Hapala and Havran 2013,
// "Fast insertion-based optimization of bounding volume hierarchies"; the
// batch-wise variant of Meister and Bittner 2018, "Parallel reinsertion for
// bounding volume hierarchy optimization", run sequentially).
//
// Each batch takes the nodes that are most likely badly placed (largest
// A(N) * A(N)/A_min(children) * A(N)/A_mean(children), Bittner's combined
// measure; leaves rank by area), and for each one in turn removes the
// subtree (its parent disappears, the sibling takes the parent's place) and
// reinserts it as the sibling of the node where the SAH cost grows least,
// found by a branch-and-bound search from the root. The old position is
// always among the candidates, so a move never raises the SAH; moves that
// would push a leaf below kBvhMaxDepth are not considered. Batches repeat
// until one improves the cost by less than 0.1% (at most kDefaultBatches), or
// exactly ReinsertionOptions::iterations times. Leaves keep their primitives, so
// only inner node areas change. The result is re-emitted in canonical
// depth-first order, and kept only if its SAH is not above the input's.
#include "accel/bvh/optimize/reinsertion.h"

#include <algorithm>
#include <cstdint>
#include <functional>
#include <queue>
#include <utility>
#include <vector>

#include "accel/bvh/builders/sweep_common.h"
#include "core/parallel.h"
#include "rayforge/core/memory_budget.h"

namespace rf {
namespace {

constexpr int kDefaultBatches = 20;
constexpr double kMinBatchImprovement = 1e-3;  // relative SAH gain of a batch worth another one
constexpr double kBatchFraction = 0.10;        // share of the nodes reinserted per batch
constexpr uint32_t kMinBatchSize = 32;
constexpr uint32_t kNone = UINT32_MAX;

struct Node {
    Box3f box;
    uint32_t left = kNone, right = kNone, parent = kNone;
    uint32_t first = 0, count = 0;  // leaves: primitive slots (count > 0)
    int height = 0;                 // inner nodes on the longest path down to a leaf
    [[nodiscard]] bool leaf() const { return count != 0; }
};

inline double area(const Box3f& b) { return b.surface_area(); }

class Reinserter {
public:
    Reinserter(const Bvh& bvh, const SahCosts& sah)
        : traversal_cost_(sah.traversal), intersection_cost_(sah.intersection) {
        budgeted_resize(nodes_, bvh.nodes.size(), "BVH reinsertion: nodes");
        // Canonical order puts children after their parent, so a reverse pass
        // sees both children before the parent.
        for (uint32_t i = 0; i < bvh.nodes.size(); ++i) {
            const BvhNode& in = bvh.nodes[i];
            Node& n = nodes_[i];
            n.box = in.bounds;
            if (in.is_leaf()) {
                n.first = in.first;
                n.count = in.count;
            } else {
                n.left = in.first;
                n.right = in.first + 1;
                nodes_[n.left].parent = i;
                nodes_[n.right].parent = i;
            }
        }
        for (uint32_t i = static_cast<uint32_t>(nodes_.size()); i-- > 0;) {
            Node& n = nodes_[i];
            if (!n.leaf()) n.height = 1 + std::max(nodes_[n.left].height, nodes_[n.right].height);
        }
    }

    void run(int iterations) {
        if (nodes_.size() < 5) return;  // nothing can move below the root's children
        const int batches = iterations > 0 ? iterations : kDefaultBatches;
        double cost = inner_area_sum();
        for (int batch = 0; batch < batches; ++batch) {
            for (const uint32_t node : pick_batch()) {
                if (nodes_[node].parent != root_ && node != root_) reinsert(node);
            }
            const double new_cost = inner_area_sum();
            const double gain = cost - new_cost;
            cost = new_cost;
            if (iterations <= 0 && !(gain > kMinBatchImprovement * total_cost(cost))) break;
        }
    }

    // The tree in the canonical layout: nodes in depth-first order with each
    // children pair adjacent (a node's pair, then the left subtree's
    // descendants, then the right's), and `original`'s leaf slots renumbered
    // in the order the leaves are laid out.
    [[nodiscard]] Bvh emit(const Bvh& original) const {
        Bvh bvh;
        budgeted_resize(bvh.nodes, nodes_.size(), "BVH nodes");
        budgeted_resize(bvh.prim_indices, original.prim_indices.size(), "BVH primitive indices");
        std::vector<std::pair<uint32_t, uint32_t>> stack;  // (node, output index)
        stack.reserve(2 * kBvhMaxDepth + 4);
        stack.emplace_back(root_, 0u);
        uint32_t next_node = 1, next_slot = 0;
        while (!stack.empty()) {
            const auto [from, at] = stack.back();
            stack.pop_back();
            const Node& node = nodes_[from];
            BvhNode& out = bvh.nodes[at];
            out.bounds = node.box;
            if (node.leaf()) {
                out.first = next_slot;
                out.count = node.count;
                for (uint32_t i = 0; i < node.count; ++i) {
                    bvh.prim_indices[next_slot++] = original.prim_indices[node.first + i];
                }
                continue;
            }
            out.first = next_node;
            out.count = 0;
            next_node += 2;
            stack.emplace_back(node.right, out.first + 1);  // popped after the left subtree is done
            stack.emplace_back(node.left, out.first);
        }
        return bvh;
    }

private:
    // Only inner areas change under reinsertion (leaves keep their boxes).
    [[nodiscard]] double inner_area_sum() const {
        double sum = 0.0;
        for (const Node& n : nodes_) sum += n.leaf() ? 0.0 : area(n.box);
        return sum;
    }
    // The full (unnormalised) SAH, given the inner area sum.
    [[nodiscard]] double total_cost(double inner_areas) const {
        double leaves = 0.0;
        for (const Node& n : nodes_) leaves += n.leaf() ? area(n.box) * n.count : 0.0;
        return traversal_cost_ * inner_areas + intersection_cost_ * leaves;
    }

    // The nodes to move this batch, worst first (ties by index: the same on every run).
    std::vector<uint32_t> pick_batch() const {
        const auto count = static_cast<uint32_t>(nodes_.size());
        std::vector<double> measure(count, -1.0);
        parallel::for_range(0u, count, 4096u, [&](uint32_t lo, uint32_t hi) {
            for (uint32_t i = lo; i != hi; ++i) {
                const Node& n = nodes_[i];
                if (i == root_ || n.parent == root_) continue;
                const double a = area(n.box);
                if (n.leaf()) {
                    measure[i] = a;
                    continue;
                }
                const double l = area(nodes_[n.left].box), r = area(nodes_[n.right].box);
                const double smallest = std::min(l, r), mean = 0.5 * (l + r);
                measure[i] = smallest > 0.0 ? a * (a / smallest) * (a / mean) : a * (mean > 0.0 ? a / mean : 1.0);
            }
        });
        std::vector<uint32_t> order;
        order.reserve(count);
        for (uint32_t i = 0; i < count; ++i) {
            if (measure[i] >= 0.0) order.push_back(i);
        }
        const auto batch = static_cast<size_t>(
            std::min<double>(order.size(), std::max<double>(kMinBatchSize, kBatchFraction * count)));
        auto worse = [&](uint32_t a, uint32_t b) { return measure[a] > measure[b] || (measure[a] == measure[b] && a < b); };
        std::partial_sort(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(batch), order.end(), worse);
        order.resize(batch);
        return order;
    }

    // Recomputes boxes and heights from `from` up to the root; returns the
    // sum of (old area - new area) over those nodes.
    double refit_up(uint32_t from) {
        double shrink = 0.0;
        for (uint32_t i = from; i != kNone; i = nodes_[i].parent) {
            Node& n = nodes_[i];
            const Node& l = nodes_[n.left];
            const Node& r = nodes_[n.right];
            const double old_area = area(n.box);
            n.box = Box3f{sweep::vmin(l.box.lo, r.box.lo), sweep::vmax(l.box.hi, r.box.hi)};
            n.height = 1 + std::max(l.height, r.height);
            shrink += old_area - area(n.box);
        }
        return shrink;
    }

    void replace_child(uint32_t parent, uint32_t old_child, uint32_t new_child) {
        if (parent == kNone) {
            root_ = new_child;
        } else if (nodes_[parent].left == old_child) {
            nodes_[parent].left = new_child;
        } else {
            nodes_[parent].right = new_child;
        }
        nodes_[new_child].parent = parent;
    }

    // Makes `spare` the parent of `node` and `target`, in target's place.
    void insert(uint32_t node, uint32_t target, uint32_t spare, bool node_left) {
        replace_child(nodes_[target].parent, target, spare);
        Node& p = nodes_[spare];
        p.left = node_left ? node : target;
        p.right = node_left ? target : node;
        nodes_[node].parent = spare;
        nodes_[target].parent = spare;
        refit_up(spare);
    }

    void reinsert(uint32_t node) {
        const uint32_t parent = nodes_[node].parent;
        const bool node_left = nodes_[parent].left == node;
        const uint32_t sibling = node_left ? nodes_[parent].right : nodes_[parent].left;
        const uint32_t grandparent = nodes_[parent].parent;

        // Remove: the sibling takes the parent's place. What that saves is
        // exactly what reinserting at the old place would cost.
        replace_child(grandparent, parent, sibling);
        const double saved = area(nodes_[parent].box) + refit_up(grandparent);

        double best = kInfinity;
        uint32_t target = find_best_target(node, best);
        if (!(best < saved * (1.0 - 1e-9))) target = sibling;  // no real gain: restore the old place
        insert(node, target, parent, target == sibling ? node_left : false);
    }

    // Branch and bound over insertion points: inserting next to X costs the
    // new parent's area A(X u N) plus the growth of X's ancestors ("induced"
    // cost); a subtree is skipped once its lower bound, induced + A(N), cannot
    // beat the best found.
    uint32_t find_best_target(uint32_t node, double& best) {
        const Box3f& box = nodes_[node].box;
        const double node_area = area(box);
        const int node_height = nodes_[node].height;
        uint32_t best_target = kNone;
        queue_.clear();
        queue_.push_back({0.0, root_, 0});
        while (!queue_.empty()) {
            std::pop_heap(queue_.begin(), queue_.end(), std::greater<>{});
            const Candidate c = queue_.back();
            queue_.pop_back();
            if (c.induced + node_area >= best) break;  // the heap's minimum: nothing left can win
            const Node& x = nodes_[c.node];
            const double direct = area(merge(x.box, box));
            const double total = c.induced + direct;
            if (total < best && c.depth + 1 + std::max(x.height, node_height) <= kBvhMaxDepth) {
                best = total;
                best_target = c.node;
            }
            if (x.leaf()) continue;
            const double child_induced = total - area(x.box);
            if (child_induced + node_area >= best) continue;
            for (const uint32_t child : {x.left, x.right}) {
                queue_.push_back({child_induced, child, c.depth + 1});
                std::push_heap(queue_.begin(), queue_.end(), std::greater<>{});
            }
        }
        return best_target;
    }

    struct Candidate {
        double induced;
        uint32_t node;
        int depth;
        bool operator>(const Candidate& o) const {
            return induced > o.induced || (induced == o.induced && node > o.node);
        }
    };

    double traversal_cost_;
    double intersection_cost_;
    std::vector<Node> nodes_;
    uint32_t root_ = 0;
    std::vector<Candidate> queue_;
};

}  // namespace

void optimize_reinsertion(Bvh& bvh, std::span<const Triangle> /*triangles*/, const SahCosts& sah,
                          const ReinsertionOptions& reinsertion) {
    if (bvh.nodes.size() < 5) return;
    Reinserter reinserter(bvh, sah);
    reinserter.run(reinsertion.iterations);
    Bvh optimized = reinserter.emit(bvh);
    // Guards against rounding: the input stays unless the SAH really did not rise.
    if (optimized.sah_cost(sah.traversal, sah.intersection) <= bvh.sah_cost(sah.traversal, sah.intersection)) {
        bvh = std::move(optimized);
    }
}

}  // namespace rf
