// Bottom-up BVH refit, after the box pass of Karras 2012 ("Maximizing
// Parallelism in the Construction of BVHs, Octrees, and k-d Trees", HPG
// 2012, sec. 4), applied to an existing tree: the topology is kept and every
// box recomputed from the triangles' current positions. The per-frame
// update of UpdateMethod::Refit (Garanzha 2014 ch. 2's first stage).
//
// Data layout: the canonical Bvh in place; a RefitPlan made once per
// topology holds a parent per node, the leaves' node indices and an arrival
// counter per node (refit_steps.h resets each counter when its second child
// arrives, so the plan needs no clearing between frames).
//
// Parallelism (TBB via core/parallel.h): the parents in a loop over
// nodes; the refit in a loop over leaves, each leaf climbing until it is the
// first of two children to reach a node, exactly the CUDA kernel's schedule
// (backend/cuda/bvh_refit.cu). The wide layouts (BVH4/8) are refitted by a
// recursion over wide nodes whose upper levels run their slots as tasks.
//
// Determinism: a node's box is always box_union(left, right) with
// std::min/max semantics, whichever child arrived last, so the boxes are
// bit-identical to the serial reference for any thread count and on the
// device.
#include "accel/bvh/refit.h"

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "accel/bvh/refit_steps.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"

namespace rf {

namespace {

constexpr size_t kNodeGrain = 4096;  // nodes per task when finding parents
constexpr size_t kLeafGrain = 512;   // leaves per task when refitting

refit::RefitView refit_view(Bvh& bvh, std::span<const Triangle> triangles, RefitPlan& plan) {
    return {bvh.nodes.data(), plan.parents.data(), bvh.prim_indices.data(), triangles.data(), plan.arrivals.data()};
}

}  // namespace

RefitPlan make_refit_plan(const Bvh& bvh) {
    RefitPlan plan;
    const size_t n = bvh.nodes.size();
    plan.parents.resize(n);
    plan.arrivals.assign(n, 0);
    parallel::for_range(size_t(0), n, kNodeGrain, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) refit::parent_step(bvh.nodes.data(), uint32_t(i), plan.parents.data());
    });
    for (size_t i = 0; i < n; ++i) {
        if (bvh.nodes[i].is_leaf()) plan.leaves.push_back(uint32_t(i));
    }
    return plan;
}

void refit_bvh(Bvh& bvh, std::span<const Triangle> triangles) {
    RefitPlan plan = make_refit_plan(bvh);
    refit_bvh(bvh, triangles, plan);
}

void refit_bvh(Bvh& bvh, std::span<const Triangle> triangles, RefitPlan& plan) {
    if (plan.parents.size() != bvh.nodes.size() || plan.arrivals.size() != bvh.nodes.size()) {
        throw Error("refit_bvh: the refit plan was made for another tree");
    }
    const refit::RefitView view = refit_view(bvh, triangles, plan);
    parallel::for_range(size_t(0), plan.leaves.size(), kLeafGrain, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) refit::refit_from_leaf<karras::AtomicArrival>(view, plan.leaves[i]);
    });
}

void refit_bvh_serial(Bvh& bvh, std::span<const Triangle> triangles) {
    if (bvh.nodes.empty()) return;
    const refit::RefitView view{bvh.nodes.data(), nullptr, bvh.prim_indices.data(), triangles.data(), nullptr};
    // Post-order with an explicit stack: any node order, any depth.
    struct Frame {
        uint32_t node;
        bool children_done;
    };
    std::vector<Frame> stack{{0, false}};
    while (!stack.empty()) {
        const Frame frame = stack.back();
        stack.pop_back();
        BvhNode& node = bvh.nodes[frame.node];
        if (node.is_leaf()) {
            node.bounds = refit::leaf_box(view, node.first, node.count);
        } else if (!frame.children_done) {
            stack.push_back({frame.node, true});
            stack.push_back({node.first + 1, false});
            stack.push_back({node.first, false});
        } else {
            node.bounds = karras::box_union(bvh.nodes[node.first].bounds, bvh.nodes[node.first + 1].bounds);
        }
    }
}

// ---------------------------------------------------------------------------
// Wide layouts: the slots' boxes and the packs rewritten in place.

namespace {

template <int N>
class WideRefitter {
public:
    WideRefitter(WideBvh<N>& wide, std::span<const Triangle> triangles) : wide_(wide), triangles_(triangles) {}

    void run() {
        if (wide_.nodes.empty()) return;
        const Box3f root = refit_node(0, 0);
        // As collapse_bvh sets it from the root's box.
        float scale = 1.0f;
        for (int axis = 0; axis < 3; ++axis) scale = std::fmax(scale, std::fmax(std::fabs(root.lo[axis]), std::fabs(root.hi[axis])));
        wide_.coord_scale = scale;
    }

private:
    static constexpr int kParallelDepth = 3;  // wide levels whose slots run as tasks

    // Refits wide node w's slots (their subtrees first); returns their union.
    Box3f refit_node(uint32_t w, int depth) {
        WideNode<N>& node = wide_.nodes[w];
        int used = 0;
        while (used < N && node.child[used] != kWideEmptyRef) ++used;
        Box3f boxes[N];
        auto slot = [&](int c) {
            const uint32_t ref = node.child[c];
            boxes[c] = wide_is_leaf(ref) ? refit_leaf(ref) : refit_node(ref, depth + 1);
            set_slot(node, c, boxes[c]);
        };
        if (depth < kParallelDepth) {
            parallel::for_range(0, used, 1, [&](int lo, int hi) {
                for (int c = lo; c < hi; ++c) slot(c);
            });
        } else {
            for (int c = 0; c < used; ++c) slot(c);
        }
        Box3f all = boxes[0];
        for (int c = 1; c < used; ++c) all = karras::box_union(all, boxes[c]);
        return all;
    }

    static void set_slot(WideNode<N>& node, int c, const Box3f& box) {
        node.bounds[0][c] = box.lo.x;
        node.bounds[1][c] = box.hi.x;
        node.bounds[2][c] = box.lo.y;
        node.bounds[3][c] = box.hi.y;
        node.bounds[4][c] = box.lo.z;
        node.bounds[5][c] = box.hi.z;
    }

    // Rewrites the leaf's packs as collapse_bvh's pack_leaf fills them and
    // returns the box of all its triangles (zero-area ones included, as the
    // binary tree's boxes include them).
    Box3f refit_leaf(uint32_t ref) {
        const float nan = std::numeric_limits<float>::quiet_NaN();
        const uint32_t first = wide_leaf_first_pack(ref);
        Box3f box;
        bool any = false;
        for (uint32_t p = first; p < first + wide_leaf_pack_count(ref); ++p) {
            TrianglePack& pack = wide_.packs[p];
            for (int lane = 0; lane < kTrianglePackWidth; ++lane) {
                if (pack.prim[lane] == kInvalidId) continue;  // stays NaN
                const Triangle& tri = triangles_[pack.prim[lane]];
                const Box3f tri_box = refit::triangle_box(tri);
                box = any ? karras::box_union(box, tri_box) : tri_box;
                any = true;
                const Vec3f normal = cross(tri.v1 - tri.v0, tri.v2 - tri.v0);
                const bool usable = !(normal.x == 0.0f && normal.y == 0.0f && normal.z == 0.0f);
                const Vec3f* vertices[3] = {&tri.v0, &tri.v1, &tri.v2};
                for (int vertex = 0; vertex < 3; ++vertex) {
                    for (int axis = 0; axis < 3; ++axis) pack.v[vertex][axis][lane] = usable ? (*vertices[vertex])[axis] : nan;
                }
            }
        }
        return box;
    }

    WideBvh<N>& wide_;
    std::span<const Triangle> triangles_;
};

}  // namespace

template <int N>
void refit_wide_bvh(WideBvh<N>& wide, std::span<const Triangle> triangles) {
    WideRefitter<N>(wide, triangles).run();
}

template void refit_wide_bvh<4>(WideBvh<4>&, std::span<const Triangle>);
template void refit_wide_bvh<8>(WideBvh<8>&, std::span<const Triangle>);

}  // namespace rf
