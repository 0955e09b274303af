// The per-frame BVH update of Garanzha 2014 ch. 2 (dissertation; paper:
// Garanzha 2008, "Efficient Clustered BVH Update Algorithm for
// Highly-Dynamic Models", IRT 2008): UpdateMethod::Adapt.
//
// Stages per frame, as the text gives them:
//  1. adaptation: a post-order refit; each inner node N is tested with eq.
//     1.3 (SAHCost with the build's SahCosts) against SavedSAHCost(N):
//     migrating when SAH/Saved < 1 - dM (N goes to MigrateBuffer; never the
//     root, which cannot be detached), exploded when MaxOverlap(N) (eq. 2.2)
//     > max_overlap and SAH/Saved > 1 + dE (N goes to RebuildBuffer and is
//     locked; descendants in RebuildBuffer whose box meets OverlapBV(NL,NR)
//     are unlocked; N's descendants leave MigrateBuffer);
//  2. rebuild: every root in RebuildBuffer is rebuilt over its region's
//     primitives (the region's leaf boxes and the locked subtrees below it,
//     as indivisible boxes weighted by Count; a leaf whose box grew past
//     kLeafGrowth times its area when built gives its triangles one by one
//     instead, so leaves spanning separating fragments are regrouped) by a
//     binned SAH over boxes (this file: RegionBuilder), new leaves of at
//     most max_leaf_size triangles; Count and SavedSAHCost recomputed;
//  3. migration: MigrateBuffer's nodes in four passes: detach N (its parent
//     is freed, its sibling takes the parent's place; N is freed and its
//     children wait), re-adapt the boxes upward from the detachment point
//     until a box stops changing, find X (the first node upward whose box
//     contains BV(N)), insert N's children from X by recursive insertion:
//     merge (a new node over X and the subtree), or descend into XL or XR,
//     whichever gives the lowest eq. 1.3 for X's configuration (all three
//     share the box X u N, so the numerators are compared); a descent that
//     creates or grows the overlap of XL and XR inserts the subtree's two
//     children from X instead (split N). Count, BV and SavedSAHCost are
//     updated on the way down. Each inserted subtree ends in one merge, so
//     the nodes freed equal the nodes created.
//
// The text's inconsistencies (Garanzha 2014, ch. 2), resolved:
//  - dM/dE readings: AdaptOptions::stated() and ::closing() (both tested).
//  - MigrateBuffer is filled in post-order but "processed from the end so
//    lower levels go first": the buffer is sorted by depth, deepest first
//    (stable, so equal depths keep post-order), and every pass runs in that
//    order. A node freed by an earlier detach (it was the parent of a
//    deeper migrating node) is skipped: its children's separation was
//    resolved by that detach.
//  - An unlocked descendant exploded node leaves RebuildBuffer: it is
//    absorbed into the ancestor's region.
//  - Region primitives: the text's leaf boxes (four times fewer primitives
//    than triangles, and the leaves' nodes are kept), except leaves grown
//    past kLeafGrowth (see stage 2), whose triangles are regrouped.
//  - Insertion SAH: eq. 1.3 of the configuration at X (see above).
//  - Counts are kept exact: a detach subtracts Count(N) from every
//    ancestor, an insertion adds it back on its path (the text's early stop
//    applies to the boxes only). SavedSAHCost is left alone on detachment
//    paths, so a node thinned by detaches is caught by eq. 2.1 later, as the
//    text intends.
//  - Nodes referenced across passes that a pass frees are forwarded to the
//    node that took their place; a start node found inside a detached
//    subtree jumps to that subtree's detachment point; an insertion never
//    starts inside the subtree it inserts.
//  - Depth: an update that leaves a path of more than kBvhMaxDepth inner
//    nodes rebuilds the whole tree with the region builder from the root
//    (whose median fallback keeps every path within the limit), counted as a
//    rebuilt subtree. Rare; the tests count it.
//
// Data layout: AdaptNode (48 bytes: box, children, parent, Count,
// SavedSAHCost (a leaf: its area when built), leaf size, Locked) in one
// linear array managed by the node memory manager (node_memory_manager.h:
// an octary tree of free counts; every node is allocated at the free slot
// nearest its parent); a leaf's triangles sit in a block of max_leaf_size
// slots at its node index. A rebuilt region's new nodes take the region's
// old slots in address order, depth first (no search; the memory manager
// only for the difference), so they stay where the region was. A region's
// scratch tree is one array of 2P - 1 slots in which every subtree owns a
// fixed range (RegionBuilder), so tasks never merge their output. The
// canonical Bvh (siblings adjacent, depth-first) is exported only when the
// topology changed; otherwise its boxes are copied in place from the
// refitted nodes through source_ (canonical index -> node), and update()
// returns false, so the dynamic accel refits its wide layout instead of
// collapsing it again. Boxes grow with plain compares (grow/joined), not
// Vec3f's min/max, whose fminf/fmaxf library calls (not inlined) were about
// a tenth of the update's profile.
//
// Parallelism (TBB via core/parallel.h): stage 1 recurses into the
// two children of large subtrees as tasks, each with its own buffers,
// appended left then right (the serial post-order); stage 2 collects and
// builds every region in parallel, large region nodes bound and bin their
// primitives in parallel and build their children as tasks; the regions
// are then linked into the tree one after another in buffer order (serial:
// the memory manager); stage 3 is serial; the export counts leaves per
// subtree and then writes every large subtree as a task at its offset.
//
// Measured (2 threads, 2-core machine; tests/bvh_adapt_test.cpp
// DISABLED_MeasureStagesOnBuiltinScenes): the rebuild stage still
// dominates; with dE = 0.01 thousands of small regions are flagged every
// frame (rotation alone moves a rigid pair's SAH by more than 1%), so an
// update costs 0.7-1.1 full binned builds on explode, nbody and cloth;
// frames without restructuring cost the refit alone, a tenth of a build.
// With the closing reading (dM = 0.01) stage 3 (serial) dominates.
//
// Determinism: buffers, region builds and the order of every allocation
// are independent of the schedule, so the tree is the same for any thread
// count.
#include "accel/update/adapt.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <string>

#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"



namespace rf {
namespace {

constexpr uint32_t kNone = AdaptBvh::kNone;
constexpr uint32_t kTag = 0x80000000u;        // parent field of a detached subtree's root: kTag | record
constexpr uint32_t kParallelAdapt = 8192;     // triangles under a node to refit its children as tasks
constexpr uint32_t kParallelRegion = 4096;    // primitives of a region node to build its children as tasks
constexpr int kMaxBins = 16;                  // bin_count (default 16) is clamped to this: bins live on the stack
constexpr size_t kBinnedRegion = 2048;        // triangles of a region without kept nodes to build with build_binned_sah
constexpr uint32_t kParallelExport = 16384;   // triangles under a node to export its children as tasks
constexpr float kLeafGrowth = 2.0f;           // a leaf grown past this factor of its built area is regrouped

bool real(uint32_t id) { return id != kNone && (id & kTag) == 0; }

// Box growth with plain compares: Vec3f's min/max call libm's fminf/fmaxf,
// which are not inlined here. Boxes hold no NaNs, so the result is the same.
inline float lower(float a, float b) { return b < a ? b : a; }
inline float upper(float a, float b) { return b > a ? b : a; }
inline void grow(Box3f& b, const Vec3f& p) {
    b.lo = {lower(b.lo.x, p.x), lower(b.lo.y, p.y), lower(b.lo.z, p.z)};
    b.hi = {upper(b.hi.x, p.x), upper(b.hi.y, p.y), upper(b.hi.z, p.z)};
}
inline void grow(Box3f& b, const Box3f& o) {
    b.lo = {lower(b.lo.x, o.lo.x), lower(b.lo.y, o.lo.y), lower(b.lo.z, o.lo.z)};
    b.hi = {upper(b.hi.x, o.hi.x), upper(b.hi.y, o.hi.y), upper(b.hi.z, o.hi.z)};
}
inline Box3f joined(const Box3f& a, const Box3f& b) {
    Box3f out = a;
    grow(out, b);
    return out;
}
inline Box3f bounds_of(const Triangle& t) {
    Box3f b{t.v0, t.v0};
    grow(b, t.v1);
    grow(b, t.v2);
    return b;
}

Box3f overlap_box(const Box3f& a, const Box3f& b) { return {max(a.lo, b.lo), min(a.hi, b.hi)}; }
bool same(const Box3f& a, const Box3f& b) { return a.lo == b.lo && a.hi == b.hi; }

// A region primitive: a triangle (tri) or a locked subtree (node id).
struct Prim {
    Box3f box;
    Vec3f centre;
    uint32_t id = 0;
    uint32_t weight = 1;  // triangles: Count of a subtree, 1 for a triangle
    bool tri = true;
};

// A node of a region's new topology. Leaf: n > 0 triangles at
// prims[first ..]; existing != kNone: a locked subtree; else inner.
struct ScratchNode {
    Box3f box;
    uint32_t child[2] = {0, 0};
    uint32_t first = 0, n = 0;
    uint32_t existing = kNone;
};

int median_levels(uint64_t count, uint32_t leaf_size) {
    const uint64_t leaves = (count + leaf_size - 1) / leaf_size;
    int levels = 0;
    while ((uint64_t{1} << levels) < leaves) ++levels;
    return levels;
}

// Binned SAH (Wald 2007) over box primitives weighted by their triangle
// counts, with the object median where no bin boundary splits or where the
// depth limit is near (depth counts from the tree's root). The subtree over
// prims [b, e) with its root at slot `at` owns the scratch slots
// [at, at + 2 (e - b) - 1): the left child's subtree from at + 1, the right
// child's from at + 2 (mid - b), so subtrees built as tasks write their own
// slots and nothing is merged afterwards.
class RegionBuilder {
public:
    RegionBuilder(const BuildOptions& build, std::vector<Prim>& prims, std::vector<ScratchNode>& out)
        : sah_(build.sah), leaf_(uint32_t(build.max_leaf_size)),
          bins_(std::clamp(build.binned.bin_count, 2, kMaxBins)), prims_(prims), out_(out) {
        out_.resize(2 * prims_.size() - 1);
    }

    void build(uint32_t at, uint32_t b, uint32_t e, int depth) {
        ScratchNode& node = out_[at];
        node = ScratchNode{};
        const uint32_t n = e - b;
        if (n == 1 && !prims_[b].tri) {
            node.existing = prims_[b].id;
            node.box = prims_[b].box;
            return;
        }
        const Bounds bounds = n >= kParallelBinning ? parallel_bounds(b, e) : bounds_of(b, e);
        node.box = bounds.box;
        const float area = node.box.surface_area();
        const Split split = find_split(b, e, bounds.centres);
        if (bounds.all_tris && n <= leaf_ &&
            (!split.valid() ||
             sah_.traversal * area + sah_.intersection * split.cost >= sah_.intersection * area * float(bounds.weight))) {
            node.first = b;
            node.n = n;
            return;
        }
        const bool depth_ok = depth + 1 + median_levels(n, bounds.all_tris ? leaf_ : 1) <= kBvhMaxDepth;
        uint32_t mid = b;
        if (split.valid() && depth_ok) mid = partition(b, e, bounds.centres, split);
        if (mid == b || mid == e) mid = median(b, e, bounds.centres);
        const uint32_t left = at + 1, right = at + 2 * (mid - b);
        node.child[0] = left;
        node.child[1] = right;
        if (n >= kParallelRegion) {
            parallel::invoke([&] { build(left, b, mid, depth + 1); }, [&] { build(right, mid, e, depth + 1); });
        } else {
            build(left, b, mid, depth + 1);
            build(right, mid, e, depth + 1);
        }
    }

private:
    static constexpr uint32_t kParallelBinning = 32 * 1024;  // prims of a node to bound and bin in parallel

    struct Split {
        int axis = -1, bin = 0;
        float cost = INFINITY;
        [[nodiscard]] bool valid() const { return axis >= 0; }
    };
    struct Bounds {
        Box3f box, centres;
        uint64_t weight = 0;
        bool all_tris = true;
        void add(const Bounds& o) {
            grow(box, o.box);
            grow(centres, o.centres);
            weight += o.weight;
            all_tris = all_tris && o.all_tris;
        }
    };
    // The bins of all three axes, filled in one pass over the primitives.
    struct Bins {
        Box3f box[3][kMaxBins];
        float weight[3][kMaxBins] = {};  // triangle counts (exact below 2^24)
        uint32_t used[3] = {0, 0, 0};      // bit i: bin i holds a primitive
        void add(const Bins& o, int bins) {
            for (int a = 0; a < 3; ++a) {
                used[a] |= o.used[a];
                for (int i = 0; i < bins; ++i) {
                    grow(box[a][i], o.box[a][i]);
                    weight[a][i] += o.weight[a][i];
                }
            }
        }
    };
    struct Binning {  // bin = (c - lo) * scale, per axis; scale 0 on a flat axis
        Vec3f lo, scale;
    };

    Bounds bounds_of(uint32_t b, uint32_t e) const {
        Bounds out;
        for (uint32_t i = b; i < e; ++i) {
            grow(out.box, prims_[i].box);
            grow(out.centres, prims_[i].centre);
            out.weight += prims_[i].weight;
            out.all_tris = out.all_tris && prims_[i].tri;
        }
        return out;
    }
    Bounds parallel_bounds(uint32_t b, uint32_t e) const {
        return parallel::reduce<uint32_t>(
            b, e, 8192, Bounds{}, [&](uint32_t lo, uint32_t hi, Bounds acc) { acc.add(bounds_of(lo, hi)); return acc; },
            [](Bounds x, const Bounds& y) { x.add(y); return x; });
    }

    [[nodiscard]] Binning binning(const Box3f& centres) const {
        Binning m;
        m.lo = centres.lo;
        for (int a = 0; a < 3; ++a) {
            const float extent = centres.hi[a] - centres.lo[a];
            m.scale[a] = extent > 0.0f ? float(bins_) / extent : 0.0f;
        }
        return m;
    }
    [[nodiscard]] int bin_of(float c, int axis, const Binning& m) const {
        return std::clamp(int((c - m.lo[axis]) * m.scale[axis]), 0, bins_ - 1);
    }

    void fill(Bins& bins, uint32_t b, uint32_t e, const Binning& m) const {
        for (uint32_t i = b; i < e; ++i) {
            const Prim& p = prims_[i];
            for (int a = 0; a < 3; ++a) {
                const int bin = bin_of(p.centre[a], a, m);
                grow(bins.box[a][bin], p.box);
                bins.weight[a][bin] += float(p.weight);
                bins.used[a] |= 1u << bin;
            }
        }
    }

    // Two primitives: the binned split separates them along the first axis
    // on which their bins differ, if any, at the cost of both boxes.
    Split split_pair(uint32_t b, const Box3f& centres) const {
        const Binning m = binning(centres);
        const Prim &p = prims_[b], &q = prims_[b + 1];
        Split best;
        for (int axis = 0; axis < 3; ++axis) {
            if (m.scale[axis] == 0.0f) continue;
            const int bp = bin_of(p.centre[axis], axis, m), bq = bin_of(q.centre[axis], axis, m);
            if (bp == bq) continue;
            const float cost = p.box.surface_area() * float(p.weight) + q.box.surface_area() * float(q.weight);
            if (cost < best.cost) best = {axis, std::max(bp, bq), cost};
        }
        return best;
    }

    Split find_split(uint32_t b, uint32_t e, const Box3f& centres) const {
        const Binning m = binning(centres);
        if (e - b == 2) return split_pair(b, centres);
        Bins bins_on_stack;
        Bins* bins = &bins_on_stack;
        if (e - b >= kParallelBinning) {
            std::vector<Bins> parts((e - b + kParallelBinning / 4 - 1) / (kParallelBinning / 4));
            parallel::for_range<size_t>(0, parts.size(), 1, [&](size_t lo, size_t hi) {
                for (size_t k = lo; k < hi; ++k) {
                    fill(parts[k], b + uint32_t(k) * (kParallelBinning / 4),
                         std::min(e, b + uint32_t(k + 1) * (kParallelBinning / 4)), m);
                }
            });
            for (const Bins& part : parts) bins->add(part, bins_);
        } else {
            fill(*bins, b, e, m);
        }
        // The sweep visits the non-empty bins only: a boundary inside a run of
        // empty bins costs what the first one after a non-empty bin costs,
        // and that first one is what a full sweep keeps (same split, same cost).
        Split best;
        for (int axis = 0; axis < 3; ++axis) {
            if (m.scale[axis] == 0.0f || std::popcount(bins->used[axis]) < 2) continue;
            int idx[kMaxBins], k = 0;
            for (uint32_t u = bins->used[axis]; u != 0; u &= u - 1) idx[k++] = std::countr_zero(u);
            float right_area[kMaxBins], right_weight[kMaxBins];
            Box3f acc;
            float w = 0.0f;
            for (int j = k - 1; j > 0; --j) {
                grow(acc, bins->box[axis][idx[j]]);
                w += bins->weight[axis][idx[j]];
                right_area[j] = acc.surface_area();
                right_weight[j] = w;
            }
            acc = Box3f();
            w = 0.0f;
            for (int j = 1; j < k; ++j) {
                grow(acc, bins->box[axis][idx[j - 1]]);
                w += bins->weight[axis][idx[j - 1]];
                const float cost = acc.surface_area() * w + right_area[j] * right_weight[j];
                if (cost < best.cost) best = {axis, idx[j - 1] + 1, cost};
            }
        }
        return best;
    }

    uint32_t partition(uint32_t b, uint32_t e, const Box3f& centres, const Split& split) {
        const Binning m = binning(centres);
        auto it = std::partition(prims_.begin() + b, prims_.begin() + e, [&](const Prim& p) {
            return bin_of(p.centre[split.axis], split.axis, m) < split.bin;
        });
        return uint32_t(it - prims_.begin());
    }

    uint32_t median(uint32_t b, uint32_t e, const Box3f& centres) {
        const int axis = centres.largest_axis();
        const uint32_t mid = b + (e - b) / 2;
        std::nth_element(prims_.begin() + b, prims_.begin() + mid, prims_.begin() + e,
                         [axis](const Prim& p, const Prim& q) {
                             if (p.centre[axis] != q.centre[axis]) return p.centre[axis] < q.centre[axis];
                             if (p.tri != q.tri) return p.tri;
                             return p.id < q.id;
                         });
        return mid;
    }

    SahCosts sah_;
    uint32_t leaf_;
    int bins_;
    std::vector<Prim>& prims_;
    std::vector<ScratchNode>& out_;
};

}  // namespace

struct AdaptBvh::Buffers {
    std::vector<uint32_t> migrate, rebuild;
    uint64_t refitted = 0;
    void append(const Buffers& other) {
        migrate.insert(migrate.end(), other.migrate.begin(), other.migrate.end());
        rebuild.insert(rebuild.end(), other.rebuild.begin(), other.rebuild.end());
        refitted += other.refitted;
    }
};

struct AdaptBvh::Region {
    uint32_t root = kNone;
    int depth = 0;
    std::vector<Prim> prims;
    std::vector<uint32_t> old_nodes;  // reused, in address order, for the new nodes; the rest freed
    std::vector<ScratchNode> nodes;
};

struct AdaptBvh::Pending {
    uint32_t child[2];
    uint32_t anchor;  // the sibling that took the detached parent's place
    uint32_t fix;     // the node whose child changed (re-adapt starts there)
    uint32_t start;   // X, found in pass 3
};

// ---------------------------------------------------------------------------
// Construction, import, export.

AdaptBvh::AdaptBvh(std::span<const Triangle> triangles, const BuildOptions& build, const AdaptOptions& options)
    : build_(build), options_(options), triangle_count_(uint32_t(triangles.size())),
      leaf_capacity_(uint32_t(std::max(build.max_leaf_size, 1))) {
    if (triangles.size() >= (size_t{1} << 30)) throw Error("adapt update: more than 2^30 triangles");
    if (!(options.migrate_threshold > 0.0f && options.migrate_threshold < 1.0f) ||
        !(options.explode_threshold > 0.0f && options.explode_threshold < 1.0f) ||
        !(options.max_overlap >= 0.0f && options.max_overlap <= 1.0f)) {
        throw Error("adapt update: dM and dE must be in (0, 1) and the overlap threshold in [0, 1]");
    }
    if (triangles.empty()) return;
    BuildOptions initial = build;
    // Spatial splits reference a triangle from several leaves; the adapt tree holds each once.
    if (initial.builder == Builder::Sbvh || initial.builder == Builder::GridBvhSplit) {
        initial.builder = Builder::BinnedSah;
    }
    triangles_ = triangles;
    parallel::with_threads(build.threads, [&] {
        import(build_bvh_on_cpu(triangles, initial));
        export_bvh();
    });
}

void AdaptBvh::import(const Bvh& bvh) {
    const uint32_t capacity = 2 * triangle_count_ - 1;
    nodes_.assign(capacity, AdaptNode{});
    slots_.assign(size_t(capacity) * leaf_capacity_, 0);
    forward_.assign(capacity, kNone);
    memory_.reset(capacity, uint32_t(bvh.nodes.size()));
    for (uint32_t i = 0; i < bvh.nodes.size(); ++i) {
        const BvhNode& in = bvh.nodes[i];
        AdaptNode& node = nodes_[i];
        node.box = in.bounds;
        if (in.is_leaf()) {
            node.leaf_size = uint16_t(in.count);
            for (uint32_t k = 0; k < in.count; ++k) slots_[size_t(i) * leaf_capacity_ + k] = bvh.prim_indices[in.first + k];
        } else {
            node.child[0] = in.first;
            node.child[1] = in.first + 1;
            nodes_[in.first].parent = nodes_[in.first + 1].parent = i;
        }
    }
    root_ = 0;
    nodes_[0].parent = kNone;
    finish_import(0);
    leaves_.assign(capacity, 0);
    count_leaves(root_);
}

uint32_t AdaptBvh::finish_import(uint32_t id) {
    AdaptNode& node = nodes_[id];
    if (node.is_leaf()) {
        node.saved_cost = node.box.surface_area();  // a leaf's saved value: its area when built
        return node.count = node.leaf_size;
    }
    node.count = finish_import(node.child[0]) + finish_import(node.child[1]);
    node.saved_cost = sah_cost(id);
    return node.count;
}

float AdaptBvh::sah_cost(uint32_t id) const {
    const AdaptNode& node = nodes_[id];
    const float area = node.box.surface_area();
    if (node.is_leaf() || !(area > 0.0f)) return build_.sah.traversal + build_.sah.intersection * float(node.count);
    const AdaptNode& l = nodes_[node.child[0]];
    const AdaptNode& r = nodes_[node.child[1]];
    const float sum = l.box.surface_area() * float(l.count) + r.box.surface_area() * float(r.count);
    return build_.sah.traversal + build_.sah.intersection * sum / area;
}

// Leaves under each node (post-order), which place every subtree of the
// depth-first export without a serial walk. Counted at import, then kept
// current wherever Count changes (the same paths) and by the region rebuilds.
uint32_t AdaptBvh::count_leaves(uint32_t id) {
    const AdaptNode& node = nodes_[id];
    if (node.is_leaf()) return leaves_[id] = 1;
    uint32_t l = 0, r = 0;
    if (node.count > kParallelExport) {
        parallel::invoke([&] { l = count_leaves(node.child[0]); }, [&] { r = count_leaves(node.child[1]); });
    } else {
        l = count_leaves(node.child[0]);
        r = count_leaves(node.child[1]);
    }
    return leaves_[id] = l + r;
}

// Node `id` at canonical `index`; its children's pair at `pair`, the pairs
// below them from pair + 2; its triangles from `slot`. Returns the deepest leaf's depth.
int AdaptBvh::emit(uint32_t id, uint32_t index, uint32_t pair, uint32_t slot, int depth) {
    const AdaptNode& node = nodes_[id];
    BvhNode& out = bvh_.nodes[index];
    out.bounds = node.box;
    source_[index] = id;
    if (node.is_leaf()) {
        out.first = slot;
        out.count = node.leaf_size;
        std::copy_n(slots_.data() + size_t(id) * leaf_capacity_, node.leaf_size, bvh_.prim_indices.data() + slot);
        return depth;
    }
    out.first = pair;
    out.count = 0;
    const uint32_t left = node.child[0], right = node.child[1];
    const uint32_t right_pairs = pair + 2 * leaves_[left];  // the left subtree's 2 * leaves - 2 nodes come first
    const uint32_t right_slot = slot + nodes_[left].count;
    if (node.count > kParallelExport) {
        int dl = 0, dr = 0;
        parallel::invoke([&] { dl = emit(left, pair, pair + 2, slot, depth + 1); },
                         [&] { dr = emit(right, pair + 1, right_pairs, right_slot, depth + 1); });
        return std::max(dl, dr);
    }
    return std::max(emit(left, pair, pair + 2, slot, depth + 1), emit(right, pair + 1, right_pairs, right_slot, depth + 1));
}

int AdaptBvh::export_bvh() {
    const uint32_t leaves = leaves_[root_];
    bvh_.nodes.resize(2 * size_t(leaves) - 1);
    source_.resize(bvh_.nodes.size());
    bvh_.prim_indices.resize(triangle_count_);
    return emit(root_, 0, 1, 0, 0);
}

void AdaptBvh::refresh_boxes() {
    parallel::for_range<size_t>(0, bvh_.nodes.size(), 8192, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) bvh_.nodes[i].bounds = nodes_[source_[i]].box;
    });
}

// ---------------------------------------------------------------------------
// The update.

bool AdaptBvh::update(std::span<const Triangle> triangles, UpdateStats& stats) {
    if (triangles.size() != triangle_count_) {
        throw Error("adapt update: " + std::to_string(triangles.size()) + " triangles, the tree was built over " +
                    std::to_string(triangle_count_));
    }
    if (root_ == kNone) return false;
    triangles_ = triangles;
    times_ = {};
    return parallel::with_threads(build_.threads, [&] {
        using Clock = std::chrono::steady_clock;
        auto lap = [last = Clock::now()](double& into) mutable {
            const auto now = Clock::now();
            into += std::chrono::duration<double, std::milli>(now - last).count();
            last = now;
        };
        Buffers buffers;
        adapt(root_, buffers, triangles);
        stats.refitted_nodes += buffers.refitted;
        lap(times_.refit_ms);
        bool changed = false;
        if (!buffers.rebuild.empty()) {
            stats.rebuilt_nodes += rebuild(buffers.rebuild, triangles);
            stats.rebuilt_subtrees += buffers.rebuild.size();
            changed = true;
        }
        lap(times_.rebuild_ms);
        if (!buffers.migrate.empty()) {
            const uint64_t moved = migrate(buffers.migrate);
            stats.migrations += moved;
            changed = changed || moved > 0;
        }
        lap(times_.migrate_ms);
        if (!changed) {
            refresh_boxes();
            lap(times_.export_ms);
            return false;
        }
        if (export_bvh() > kBvhMaxDepth) {
            full_rebuild(triangles);
            stats.rebuilt_subtrees += 1;
            stats.rebuilt_nodes += memory_.used_count();
            export_bvh();
        }
        lap(times_.export_ms);
        return true;
    });
}

// Stage 1: post-order refit with detection.
void AdaptBvh::adapt(uint32_t id, Buffers& out, std::span<const Triangle> triangles) {
    AdaptNode& node = nodes_[id];
    ++out.refitted;
    if (node.is_leaf()) {
        Box3f box;
        for (uint32_t t : leaf_triangles(id)) grow(box, bounds_of(triangles[t]));
        node.box = box;
        return;
    }
    const size_t migrate_start = out.migrate.size(), rebuild_start = out.rebuild.size();
    if (node.count > kParallelAdapt) {
        Buffers left, right;
        parallel::invoke([&] { adapt(node.child[0], left, triangles); },
                         [&] { adapt(node.child[1], right, triangles); });
        out.append(left);
        out.append(right);
    } else {
        adapt(node.child[0], out, triangles);
        adapt(node.child[1], out, triangles);
    }
    node.box = joined(nodes_[node.child[0]].box, nodes_[node.child[1]].box);
    detect(id, out, migrate_start, rebuild_start);
}

void AdaptBvh::detect(uint32_t id, Buffers& out, size_t migrate_start, size_t rebuild_start) {
    AdaptNode& node = nodes_[id];
    const float ratio = node.saved_cost > 0.0f ? sah_cost(id) / node.saved_cost : 1.0f;
    if (options_.migrate && id != root_ && ratio < 1.0f - options_.migrate_threshold) out.migrate.push_back(id);
    if (!options_.rebuild || !(ratio > 1.0f + options_.explode_threshold)) return;
    const Box3f& l = nodes_[node.child[0]].box;
    const Box3f& r = nodes_[node.child[1]].box;
    const Box3f overlap = overlap_box(l, r);
    const float smaller = std::min(l.surface_area(), r.surface_area());
    const float max_overlap = smaller > 0.0f ? overlap.surface_area() / smaller : 0.0f;
    if (!(max_overlap > options_.max_overlap)) return;
    node.locked = 1;
    size_t kept = rebuild_start;
    for (size_t i = rebuild_start; i < out.rebuild.size(); ++i) {
        AdaptNode& inner = nodes_[out.rebuild[i]];
        if (overlap_box(inner.box, overlap).is_empty()) {
            out.rebuild[kept++] = out.rebuild[i];
        } else {
            inner.locked = 0;  // absorbed into this region
        }
    }
    out.rebuild.resize(kept);
    out.migrate.resize(std::min(out.migrate.size(), migrate_start));
    out.rebuild.push_back(id);
}

// ---------------------------------------------------------------------------
// Stage 2: local rebuilds.

bool AdaptBvh::leaf_intact(uint32_t id) const {
    const AdaptNode& leaf = nodes_[id];
    return leaf.leaf_size == 1 || leaf.box.surface_area() <= kLeafGrowth * leaf.saved_cost;
}

void AdaptBvh::collect_region(uint32_t root, Region& region) const {
    region.root = root;
    region.depth = 0;
    for (uint32_t p = nodes_[root].parent; real(p); p = nodes_[p].parent) ++region.depth;
    std::vector<uint32_t> stack = {nodes_[root].child[1], nodes_[root].child[0]};
    while (!stack.empty()) {
        const uint32_t id = stack.back();
        stack.pop_back();
        const AdaptNode& node = nodes_[id];
        if (node.locked || (node.is_leaf() && leaf_intact(id))) {
            region.prims.push_back({node.box, node.box.center(), id, node.count, false});
            continue;
        }
        region.old_nodes.push_back(id);
        if (node.is_leaf()) {
            for (uint32_t t : leaf_triangles(id)) {
                const Box3f box = bounds_of(triangles_[t]);
                region.prims.push_back({box, box.center(), t, 1, true});
            }
        } else {
            stack.push_back(node.child[1]);
            stack.push_back(node.child[0]);
        }
    }
}

void AdaptBvh::build_region(Region& region, std::span<const Triangle> triangles) const {
    const bool all_tris = std::all_of(region.prims.begin(), region.prims.end(), [](const Prim& p) { return p.tri; });
    if (all_tris && region.prims.size() >= kBinnedRegion) {
        // Triangles only: the project's binned SAH builder (the same SAH, parallel, SIMD).
        std::vector<Triangle> subset(region.prims.size());
        for (size_t i = 0; i < subset.size(); ++i) subset[i] = triangles[region.prims[i].id];
        const Bvh bvh = build_binned_sah(subset, bvh_build_config(build_), build_.binned);
        std::vector<Prim> ordered(region.prims.size());
        for (size_t i = 0; i < ordered.size(); ++i) ordered[i] = region.prims[bvh.prim_indices[i]];
        region.prims = std::move(ordered);
        region.nodes.resize(bvh.nodes.size());
        for (size_t i = 0; i < bvh.nodes.size(); ++i) {
            const BvhNode& in = bvh.nodes[i];
            ScratchNode& out = region.nodes[i];
            out.box = in.bounds;
            if (in.is_leaf()) {
                out.first = in.first;
                out.n = in.count;
            } else {
                out.child[0] = in.first;
                out.child[1] = in.first + 1;
            }
        }
        return;
    }
    RegionBuilder builder(build_, region.prims, region.nodes);
    builder.build(0, 0, uint32_t(region.prims.size()), region.depth);
}

// Links the region's new topology below `parent`, depth first; new nodes
// take the region's old slots in address order (the root keeps its own),
// then the memory manager's nearest free slots.
uint32_t AdaptBvh::apply_region(Region& region, uint32_t scratch, uint32_t id, uint32_t parent, size_t& reused) {
    const ScratchNode& in = region.nodes[scratch];
    if (in.existing != kNone) {
        nodes_[in.existing].parent = parent;
        return in.existing;
    }
    if (id == kNone) id = reused < region.old_nodes.size() ? region.old_nodes[reused++] : memory_.allocate_near(parent);
    AdaptNode& node = nodes_[id];
    node.box = in.box;
    node.parent = parent;
    node.locked = 0;
    if (in.n > 0) {
        node.leaf_size = uint16_t(in.n);
        node.count = in.n;
        leaves_[id] = 1;
        node.saved_cost = in.box.surface_area();
        for (uint32_t k = 0; k < in.n; ++k) slots_[size_t(id) * leaf_capacity_ + k] = region.prims[in.first + k].id;
        return id;
    }
    node.leaf_size = 0;
    for (int k = 0; k < 2; ++k) nodes_[id].child[k] = apply_region(region, in.child[k], kNone, id, reused);
    nodes_[id].count = nodes_[nodes_[id].child[0]].count + nodes_[nodes_[id].child[1]].count;
    leaves_[id] = leaves_[nodes_[id].child[0]] + leaves_[nodes_[id].child[1]];
    nodes_[id].saved_cost = sah_cost(id);
    return id;
}

uint64_t AdaptBvh::rebuild(std::span<const uint32_t> roots, std::span<const Triangle> triangles) {
    std::vector<Region> regions(roots.size());
    parallel::for_range<size_t>(0, regions.size(), 1, [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            collect_region(roots[i], regions[i]);
            build_region(regions[i], triangles);
        }
    });
    const auto link_start = std::chrono::steady_clock::now();
    uint64_t created = 0;
    for (Region& region : regions) {  // buffer order: nested regions first
        std::sort(region.old_nodes.begin(), region.old_nodes.end());
        size_t reused = 0;
        const uint64_t before = memory_.used_count();
        const uint32_t old_leaves = leaves_[region.root];
        apply_region(region, 0, region.root, nodes_[region.root].parent, reused);
        for (uint32_t x = nodes_[region.root].parent; real(x); x = nodes_[x].parent) {
            leaves_[x] = leaves_[x] - old_leaves + leaves_[region.root];  // the region's leaf count changed
        }
        created += reused + (memory_.used_count() - before);
        for (size_t k = reused; k < region.old_nodes.size(); ++k) memory_.free(region.old_nodes[k]);
    }
    for (uint32_t id : roots) nodes_[id].locked = 0;
    times_.link_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - link_start).count();
    return created;
}

void AdaptBvh::full_rebuild(std::span<const Triangle> triangles) {
    std::vector<uint32_t> roots = {root_};
    if (nodes_[root_].is_leaf()) return;
    rebuild(roots, triangles);
}

// ---------------------------------------------------------------------------
// Stage 3: migration.

uint32_t AdaptBvh::resolve(uint32_t id) const {
    for (int guard = 0; real(id) && forward_[id] != kNone && guard < (1 << 20); ++guard) id = forward_[id];
    return id;
}

void AdaptBvh::release(uint32_t id, uint32_t replacement) {
    memory_.free(id);
    forward_[id] = replacement;
    forwarded_.push_back(id);
}

void AdaptBvh::replace_child(uint32_t parent, uint32_t old_child, uint32_t new_child,
                             std::vector<Pending>* pending) {
    nodes_[new_child].parent = parent;
    if (parent == kNone) {
        root_ = new_child;
    } else if (parent & kTag) {
        Pending& record = (*pending)[parent & ~kTag];
        record.child[record.child[0] == old_child ? 0 : 1] = new_child;
    } else {
        AdaptNode& p = nodes_[parent];
        p.child[p.child[0] == old_child ? 0 : 1] = new_child;
    }
}

void AdaptBvh::detach(uint32_t id, std::vector<Pending>& pending) {
    if (forward_[id] != kNone || memory_.is_free(id)) return;  // freed by a deeper detach
    const uint32_t parent = nodes_[id].parent;
    if (!real(parent) || nodes_[id].is_leaf()) return;
    const AdaptNode& p = nodes_[parent];
    const uint32_t sibling = p.child[p.child[0] == id ? 1 : 0];
    const uint32_t grand = p.parent;
    replace_child(grand, parent, sibling, &pending);
    for (uint32_t x = grand; real(x); x = nodes_[x].parent) {
        nodes_[x].count -= nodes_[id].count;
        leaves_[x] -= leaves_[id];
    }
    const uint32_t record = uint32_t(pending.size());
    pending.push_back({{nodes_[id].child[0], nodes_[id].child[1]}, sibling, grand, kNone});
    nodes_[nodes_[id].child[0]].parent = nodes_[nodes_[id].child[1]].parent = kTag | record;
    release(parent, sibling);
    release(id, sibling);
}

void AdaptBvh::refit_upward(uint32_t id) {
    bool first = true;
    for (uint32_t y = resolve(id); real(y); y = nodes_[y].parent) {
        AdaptNode& node = nodes_[y];
        if (node.is_leaf()) continue;
        const Box3f box = joined(nodes_[node.child[0]].box, nodes_[node.child[1]].box);
        if (!first && same(box, node.box)) break;  // the ancestors already agree
        node.box = box;
        first = false;
    }
}

uint32_t AdaptBvh::find_start(uint32_t id, const Box3f& box, const std::vector<Pending>& pending) const {
    uint32_t y = id;
    for (int guard = 0; guard < 4096; ++guard) {
        if (y == kNone) return root_;
        if (y & kTag) {  // the root of a detached subtree: continue from where it was detached
            y = pending[y & ~kTag].anchor;
            continue;
        }
        y = resolve(y);
        if (!real(y)) continue;
        const uint32_t parent = nodes_[y].parent;
        if (parent & kTag && parent != kNone) {
            y = parent;
            continue;
        }
        if (nodes_[y].box.contains(box) || parent == kNone) return y;
        y = parent;
    }
    return root_;
}

void AdaptBvh::merge_at(uint32_t at, uint32_t id) {
    const uint32_t parent = nodes_[at].parent;
    const uint32_t u = memory_.allocate_near(real(parent) ? parent : at);
    forward_[u] = kNone;
    AdaptNode& node = nodes_[u];
    node = AdaptNode{};
    node.box = joined(nodes_[at].box, nodes_[id].box);
    node.child[0] = at;
    node.child[1] = id;
    node.count = nodes_[at].count + nodes_[id].count;
    leaves_[u] = leaves_[at] + leaves_[id];
    replace_child(parent, at, u, nullptr);
    nodes_[at].parent = nodes_[id].parent = u;
    nodes_[u].saved_cost = sah_cost(u);
}

// Recursive insertion of subtree `id` at or below `at` (whose ancestors already count it).
void AdaptBvh::descend(uint32_t at, uint32_t id) {
    const AdaptNode& n = nodes_[id];
    const float sa_n = n.box.surface_area(), c_n = float(n.count);
    for (uint32_t x = at;;) {
        AdaptNode& node = nodes_[x];
        if (node.is_leaf()) return merge_at(x, id);
        const AdaptNode& l = nodes_[node.child[0]];
        const AdaptNode& r = nodes_[node.child[1]];
        const Box3f l_n = joined(l.box, n.box), r_n = joined(r.box, n.box);
        const float cost_merge = node.box.surface_area() * float(node.count) + sa_n * c_n;
        const float cost_left = l_n.surface_area() * (float(l.count) + c_n) + r.box.surface_area() * float(r.count);
        const float cost_right = l.box.surface_area() * float(l.count) + r_n.surface_area() * (float(r.count) + c_n);
        if (cost_merge <= std::min(cost_left, cost_right)) return merge_at(x, id);
        const int side = cost_left <= cost_right ? 0 : 1;
        const float before = overlap_box(l.box, r.box).surface_area();
        const float after = side == 0 ? overlap_box(l_n, r.box).surface_area() : overlap_box(l.box, r_n).surface_area();
        if (after > before && !n.is_leaf()) {  // split N: its children go in one by one
            const uint32_t children[2] = {n.child[0], n.child[1]};
            const uint32_t above = node.parent;
            release(id, x);
            descend(x, children[0]);
            // A merge at x put a new node in x's place: the second child starts there.
            uint32_t top = x;
            while (nodes_[top].parent != above) top = nodes_[top].parent;
            descend(top, children[1]);
            return;
        }
        node.box = joined(node.box, n.box);
        node.count += n.count;
        leaves_[x] += leaves_[id];
        const float area = node.box.surface_area();
        node.saved_cost = build_.sah.traversal +
                          build_.sah.intersection * (area > 0.0f ? std::min(cost_left, cost_right) / area : c_n);
        x = node.child[side];
    }
}

void AdaptBvh::insert(uint32_t at, uint32_t id, const std::vector<Pending>& pending) {
    uint32_t x = find_start(at, nodes_[id].box, pending);
    for (uint32_t y = x; real(y); y = nodes_[y].parent) {
        if (y == id) {  // never inside the subtree being inserted
            x = root_;
            break;
        }
    }
    for (uint32_t y = nodes_[x].parent; real(y); y = nodes_[y].parent) {
        nodes_[y].count += nodes_[id].count;
        leaves_[y] += leaves_[id];
        grow(nodes_[y].box, nodes_[id].box);
    }
    descend(x, id);
}

uint64_t AdaptBvh::migrate(std::vector<uint32_t>& buffer) {
    std::vector<std::pair<int, uint32_t>> order;
    order.reserve(buffer.size());
    for (uint32_t id : buffer) {
        int depth = 0;
        for (uint32_t p = nodes_[id].parent; real(p); p = nodes_[p].parent) ++depth;
        order.push_back({depth, id});
    }
    std::stable_sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    std::vector<Pending> pending;
    for (const auto& [depth, id] : order) detach(id, pending);  // pass 1
    for (const Pending& p : pending) {                        // pass 2
        if (real(p.fix)) refit_upward(p.fix);
    }
    for (Pending& p : pending) {  // pass 3
        const Box3f box = joined(nodes_[p.child[0]].box, nodes_[p.child[1]].box);
        p.start = find_start(p.anchor, box, pending);
    }
    for (size_t i = 0; i < pending.size(); ++i) {  // pass 4
        for (int k = 0; k < 2; ++k) insert(pending[i].start, pending[i].child[k], pending);
    }
    for (uint32_t id : forwarded_) forward_[id] = kNone;
    forwarded_.clear();
    return pending.size();
}

std::unique_ptr<BvhUpdater> make_adapt_updater(std::span<const Triangle> triangles, const BuildOptions& build,
                                               const AdaptOptions& options) {
    return std::make_unique<AdaptBvh>(triangles, build, options);
}

}  // namespace rf
