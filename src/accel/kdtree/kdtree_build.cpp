// SAH kd-tree build of Zlatuška 2009 (sec. 4.2.2): binned SAH with
// min-max bins in the upper levels (Shevtsov, Soupikov and Kapustin 2007),
// the exact O(N log N) event sweep of Wald and Havran 2006 below
// kKdExactSweepThreshold references. Optional perfect splits clip straddling
// triangles to each child cell (polygon_clip.h); the SAH discounts splits
// that cut off empty space by KdTreeOptions::empty_bonus.
#include "accel/kdtree/kdtree_build.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "accel/kdtree/polygon_clip.h"
#include "core/parallel.h"
#include "rayforge/core/error.h"
#include "rayforge/core/memory_budget.h"

namespace rf {

int kdtree_max_depth(size_t triangle_count) {
    const double depth = 8.0 + 1.3 * std::log2(static_cast<double>(std::max<size_t>(triangle_count, 1)));
    return std::min(kKdMaxDepth, static_cast<int>(depth));
}

namespace {

constexpr size_t kParallelSubtreeRefs = 1024;   // subtrees over more references become tasks
constexpr size_t kParallelNodeRefs = 1 << 16;   // nodes this big bin and clip in parallel
constexpr int kMaxBins = 256;                   // BinnedSahOptions::bin_count is at most this
constexpr uint32_t kMaxEventRef = (1u << 30) - 1;
constexpr uint32_t kNoRef = 0xFFFFFFFFu;
constexpr float kInf = std::numeric_limits<float>::infinity();

struct Config {
    const Triangle* triangles = nullptr;
    float traversal_cost = 1.0f;
    float intersection_cost = 1.0f;
    float empty_factor = 0.8f;  // 1 - empty_bonus: the SAH of a split with an empty child is scaled by it
    bool perfect_splits = true;
    int max_depth = 0;
    int bins = 16;
};

// The tree as built, before it is laid out into KdNodes.
struct TempNode {
    int axis = -1;  // -1: leaf
    float split = 0.0f;
    std::unique_ptr<TempNode> below, above;
    std::vector<uint32_t> prims;
};
using TempPtr = std::unique_ptr<TempNode>;

TempPtr make_leaf(std::vector<uint32_t> prims) {
    auto node = std::make_unique<TempNode>();
    node->prims = std::move(prims);
    return node;
}

TempPtr make_inner(int axis, float split, TempPtr below, TempPtr above) {
    auto node = std::make_unique<TempNode>();
    node->axis = axis;
    node->split = split;
    node->below = std::move(below);
    node->above = std::move(above);
    return node;
}

// Builds both subtrees, as parallel tasks when the node is big enough.
template <class F, class G>
void build_both(size_t refs, F&& below, G&& above) {
    if (refs > kParallelSubtreeRefs) {
        parallel::invoke(std::forward<F>(below), std::forward<G>(above));
    } else {
        below();
        above();
    }
}

// ---------------------------------------------------------------- SAH ------

struct Split {
    int axis = -1;
    float pos = 0.0f;
    float cost = kInf;
    bool planar_below = true;  // triangles lying in the plane go below (else above)
};

// W&H's SAH along one axis of one cell. The children's areas are linear in
// the plane position: 2 (cap + (pos - lo) * side) below, the rest above.
struct AxisSah {
    const Config* c;
    int axis;
    float lo, hi;
    float cap, side;  // the cell's cross-section area and half its perimeter across the axis
    float inv_area;

    AxisSah(const Config& config, const Box3f& cell, int k, float inv_cell_area)
        : c(&config), axis(k), lo(cell.lo[k]), hi(cell.hi[k]), inv_area(inv_cell_area) {
        const int u = (k + 1) % 3, v = (k + 2) % 3;
        const float eu = cell.hi[u] - cell.lo[u], ev = cell.hi[v] - cell.lo[v];
        cap = eu * ev;
        side = eu + ev;
    }

    // Considers the plane `pos` with the triangles lying in it on the cheaper
    // side; keeps the cheapest candidate in `best` (the first one on ties).
    void consider(float pos, size_t n_below, size_t n_planar, size_t n_above, Split& best) const {
        const float p_below = 2.0f * (cap + (pos - lo) * side) * inv_area;
        const float p_above = 2.0f * (cap + (hi - pos) * side) * inv_area;
        auto cost = [&](size_t nb, size_t na) {
            // An empty child without volume cuts off nothing: never worth a node.
            if ((nb == 0 && pos <= lo) || (na == 0 && pos >= hi)) return kInf;
            float sah = c->traversal_cost +
                        c->intersection_cost * (p_below * static_cast<float>(nb) + p_above * static_cast<float>(na));
            if (nb == 0 || na == 0) sah *= c->empty_factor;
            return sah;
        };
        const float with_below = cost(n_below + n_planar, n_above);
        if (with_below < best.cost) best = {axis, pos, with_below, true};
        if (n_planar == 0) return;
        const float with_above = cost(n_below, n_above + n_planar);
        if (with_above < best.cost) best = {axis, pos, with_above, false};
    }
};

// Bounds of the part of triangle `prim` (now bounded by `box`) in `child`;
// false when none of it is there (only possible with perfect splits).
bool part_in(const Config& c, uint32_t prim, const Box3f& box, const Box3f& child, Box3f& part) {
    Box3f clipped = box;
    if (c.perfect_splits && !clip_triangle_bounds(c.triangles[prim], child, clipped)) return false;
    for (int k = 0; k < 3; ++k) {
        part.lo[k] = std::max(std::max(box.lo[k], clipped.lo[k]), child.lo[k]);
        part.hi[k] = std::min(std::min(box.hi[k], clipped.hi[k]), child.hi[k]);
        if (part.lo[k] > part.hi[k]) return false;
    }
    return true;
}

void split_cells(const Box3f& cell, const Split& s, Box3f& below, Box3f& above) {
    below = cell;
    above = cell;
    below.hi[s.axis] = s.pos;
    above.lo[s.axis] = s.pos;
}

// ------------------------------------------- exact event sweep (W&H 2006) ---

enum EventType : uint32_t { kEnd = 0, kPlanar = 1, kStart = 2 };  // the order events sort in at one position

struct Event {
    float pos;
    uint32_t key;  // type << 30 | local reference
    [[nodiscard]] uint32_t ref() const { return key & kMaxEventRef; }
    [[nodiscard]] uint32_t type() const { return key >> 30; }
};

bool operator<(const Event& a, const Event& b) { return a.pos < b.pos || (a.pos == b.pos && a.key < b.key); }

// A node of the exact stage: its references and one sorted event list per axis.
struct EventNode {
    std::vector<uint32_t> prims;  // local reference -> triangle
    std::vector<Box3f> boxes;     // local reference -> bounds of its part in the cell
    std::array<std::vector<Event>, 3> events;
};

void add_events(const Box3f& box, uint32_t ref, std::array<std::vector<Event>, 3>& events) {
    for (int k = 0; k < 3; ++k) {
        if (box.lo[k] == box.hi[k]) {
            events[k].push_back({box.lo[k], (kPlanar << 30) | ref});
        } else {
            events[k].push_back({box.lo[k], (kStart << 30) | ref});
            events[k].push_back({box.hi[k], (kEnd << 30) | ref});
        }
    }
}

EventNode make_event_node(std::vector<uint32_t> prims, std::vector<Box3f> boxes) {
    if (prims.size() > kMaxEventRef) {
        throw Error("kd-tree build: " + std::to_string(prims.size()) + " references in one node exceed 2^30");
    }
    EventNode node;
    node.prims = std::move(prims);
    node.boxes = std::move(boxes);
    for (auto& list : node.events) budgeted_reserve(list, 2 * node.prims.size(), "kd-tree events");
    for (size_t i = 0; i < node.prims.size(); ++i) add_events(node.boxes[i], static_cast<uint32_t>(i), node.events);
    for (auto& list : node.events) std::sort(list.begin(), list.end());
    return node;
}

// One sweep per axis over the sorted events: the counts below, in and above
// every candidate plane follow from the events passed (W&H, alg. 4).
Split find_split_exact(const Config& c, const EventNode& node, const Box3f& cell) {
    Split best;
    const float area = cell.surface_area();
    if (!(area > 0.0f)) return best;
    const float inv_area = 1.0f / area;
    const size_t n = node.prims.size();
    for (int axis = 0; axis < 3; ++axis) {
        if (!(cell.hi[axis] > cell.lo[axis])) continue;  // a flat cell is not split across its thickness
        const AxisSah sah(c, cell, axis, inv_area);
        const std::vector<Event>& ev = node.events[axis];
        size_t n_below = 0, n_above = n;
        for (size_t i = 0; i < ev.size();) {
            const float pos = ev[i].pos;
            size_t ends = 0, planars = 0, starts = 0;
            while (i < ev.size() && ev[i].pos == pos && ev[i].type() == kEnd) ++ends, ++i;
            while (i < ev.size() && ev[i].pos == pos && ev[i].type() == kPlanar) ++planars, ++i;
            while (i < ev.size() && ev[i].pos == pos && ev[i].type() == kStart) ++starts, ++i;
            n_above -= planars + ends;
            sah.consider(pos, n_below, planars, n_above, best);
            n_below += starts + planars;
        }
    }
    return best;
}

enum Side : uint8_t { kBoth = 0, kBelow = 1, kAbove = 2 };

// Per-thread scratch arrays of split_event_node, reused from node to node
// (a split runs on one thread from start to end).
struct SplitScratch {
    std::vector<uint8_t> side;
    std::vector<uint32_t> to_below, to_above;
    std::vector<uint32_t> fresh_below, fresh_above;
    std::array<std::vector<Event>, 3> added;
};

SplitScratch& split_scratch() {
    thread_local SplitScratch scratch;
    return scratch;
}

// Sorted events of the freshly clipped references `fresh` of `child`.
void fresh_events(const EventNode& child, const std::vector<uint32_t>& fresh, std::array<std::vector<Event>, 3>& added) {
    for (auto& list : added) list.clear();
    for (uint32_t ref : fresh) add_events(child.boxes[ref], ref, added);
    for (auto& list : added) std::sort(list.begin(), list.end());
}

// Classifies the references against the split from the events of its axis
// (W&H, alg. 5), then splits the event lists in order: the events of
// references entirely on one side keep their order, only straddlers (clipped
// to each child) get new events, sorted on their own and merged in while the
// lists are split (W&H, sec. 5.3): no full re-sort.
void split_event_node(const Config& c, EventNode& node, const Split& s, const Box3f& cell_below,
                      const Box3f& cell_above, EventNode& below, EventNode& above) {
    const size_t n = node.prims.size();
    SplitScratch& scratch = split_scratch();
    std::vector<uint8_t>& side = scratch.side;
    side.assign(n, kBoth);
    for (const Event& e : node.events[s.axis]) {
        switch (e.type()) {
            case kEnd: if (e.pos <= s.pos) side[e.ref()] = kBelow; break;
            case kStart: if (e.pos >= s.pos) side[e.ref()] = kAbove; break;
            default:
                side[e.ref()] = (e.pos < s.pos || (e.pos == s.pos && s.planar_below)) ? kBelow : kAbove;
                break;
        }
    }
    std::vector<uint32_t>& to_below = scratch.to_below;
    std::vector<uint32_t>& to_above = scratch.to_above;
    to_below.assign(n, kNoRef);
    to_above.assign(n, kNoRef);
    scratch.fresh_below.clear();
    scratch.fresh_above.clear();
    size_t n_below = 0, n_above = 0;
    for (size_t i = 0; i < n; ++i) n_below += side[i] != kAbove, n_above += side[i] != kBelow;
    below.prims.reserve(n_below);
    below.boxes.reserve(n_below);
    above.prims.reserve(n_above);
    above.boxes.reserve(n_above);
    auto add = [](EventNode& child, std::vector<uint32_t>& map, size_t i, uint32_t prim, const Box3f& box) {
        map[i] = static_cast<uint32_t>(child.prims.size());
        child.prims.push_back(prim);
        child.boxes.push_back(box);
    };
    for (size_t i = 0; i < n; ++i) {
        const uint32_t prim = node.prims[i];
        if (side[i] == kBelow) {
            add(below, to_below, i, prim, node.boxes[i]);
        } else if (side[i] == kAbove) {
            add(above, to_above, i, prim, node.boxes[i]);
        } else {
            Box3f part;
            if (part_in(c, prim, node.boxes[i], cell_below, part)) {
                add(below, to_below, i, prim, part);
                scratch.fresh_below.push_back(to_below[i]);
            }
            if (part_in(c, prim, node.boxes[i], cell_above, part)) {
                add(above, to_above, i, prim, part);
                scratch.fresh_above.push_back(to_above[i]);
            }
        }
    }
    for (int pass = 0; pass < 2; ++pass) {
        EventNode& child = pass == 0 ? below : above;
        const uint8_t wanted = pass == 0 ? kBelow : kAbove;
        const std::vector<uint32_t>& map = pass == 0 ? to_below : to_above;
        fresh_events(child, pass == 0 ? scratch.fresh_below : scratch.fresh_above, scratch.added);
        for (int k = 0; k < 3; ++k) {
            const std::vector<Event>& fresh = scratch.added[k];
            std::vector<Event>& out = child.events[k];
            out.reserve(2 * child.prims.size());
            size_t f = 0;
            for (const Event& e : node.events[k]) {
                const uint32_t i = e.ref();
                if (side[i] != wanted) continue;
                const Event moved{e.pos, (e.type() << 30) | map[i]};
                while (f < fresh.size() && fresh[f] < moved) out.push_back(fresh[f++]);
                out.push_back(moved);
            }
            out.insert(out.end(), fresh.begin() + static_cast<std::ptrdiff_t>(f), fresh.end());
        }
    }
}

TempPtr build_exact(const Config& c, EventNode node, const Box3f& cell, int depth) {
    const size_t n = node.prims.size();
    if (n == 0 || depth >= c.max_depth) return make_leaf(std::move(node.prims));
    const Split s = find_split_exact(c, node, cell);
    // Termination: splitting must beat intersecting every triangle here.
    if (s.axis < 0 || !(s.cost < c.intersection_cost * static_cast<float>(n))) return make_leaf(std::move(node.prims));
    Box3f cell_below, cell_above;
    split_cells(cell, s, cell_below, cell_above);
    EventNode below, above;
    split_event_node(c, node, s, cell_below, cell_above, below, above);
    node = EventNode{};
    TempPtr below_tree, above_tree;
    build_both(
        n, [&] { below_tree = build_exact(c, std::move(below), cell_below, depth + 1); },
        [&] { above_tree = build_exact(c, std::move(above), cell_above, depth + 1); });
    return make_inner(s.axis, s.pos, std::move(below_tree), std::move(above_tree));
}

// --------------------------------------------- binned SAH (upper levels) ---

struct Ref {
    uint32_t prim;
    Box3f box;  // bounds of the triangle's part in the cell
};

std::vector<uint32_t> prims_of(const std::vector<Ref>& refs) {
    std::vector<uint32_t> prims(refs.size());
    for (size_t i = 0; i < refs.size(); ++i) prims[i] = refs[i].prim;
    return prims;
}

TempPtr build_exact_from_refs(const Config& c, std::vector<Ref> refs, const Box3f& cell, int depth) {
    std::vector<uint32_t> prims = prims_of(refs);
    std::vector<Box3f> boxes(refs.size());
    for (size_t i = 0; i < refs.size(); ++i) boxes[i] = refs[i].box;
    std::vector<Ref>().swap(refs);
    return build_exact(c, make_event_node(std::move(prims), std::move(boxes)), cell, depth);
}

// Min-max bins: per axis, how many references start and how many end in
// each bin; the counts below and above every bin boundary follow by prefix sums.
struct Bins {
    std::array<uint32_t, 3 * kMaxBins> starts{};
    std::array<uint32_t, 3 * kMaxBins> ends{};
};

Split find_split_binned(const Config& c, const std::vector<Ref>& refs, const Box3f& cell) {
    Split best;
    const float area = cell.surface_area();
    if (!(area > 0.0f)) return best;
    const int bins = c.bins;
    float scale[3];
    for (int k = 0; k < 3; ++k) {
        const float extent = cell.hi[k] - cell.lo[k];
        scale[k] = extent > 0.0f ? static_cast<float>(bins) / extent : 0.0f;
    }
    auto bin_of = [&](int k, float x) {
        const float b = (x - cell.lo[k]) * scale[k];
        return b <= 0.0f ? 0 : std::min(bins - 1, static_cast<int>(b));
    };
    auto fill = [&](size_t lo, size_t hi, Bins acc) {
        for (size_t i = lo; i < hi; ++i) {
            for (int k = 0; k < 3; ++k) {
                ++acc.starts[k * kMaxBins + bin_of(k, refs[i].box.lo[k])];
                ++acc.ends[k * kMaxBins + bin_of(k, refs[i].box.hi[k])];
            }
        }
        return acc;
    };
    Bins total;
    if (refs.size() >= kParallelNodeRefs) {
        total = parallel::reduce(size_t(0), refs.size(), size_t(8192), Bins{}, fill, [](Bins a, const Bins& b) {
            for (size_t j = 0; j < a.starts.size(); ++j) a.starts[j] += b.starts[j], a.ends[j] += b.ends[j];
            return a;
        });
    } else {
        total = fill(0, refs.size(), Bins{});
    }
    const float inv_area = 1.0f / area;
    for (int k = 0; k < 3; ++k) {
        if (scale[k] == 0.0f) continue;
        const float extent = cell.hi[k] - cell.lo[k];
        const AxisSah sah(c, cell, k, inv_area);
        size_t n_below = 0, n_above = refs.size();
        for (int b = 1; b < bins; ++b) {
            n_below += total.starts[k * kMaxBins + b - 1];  // started in a bin below the plane
            n_above -= total.ends[k * kMaxBins + b - 1];    // ended in a bin below the plane
            const float pos = cell.lo[k] + extent * (static_cast<float>(b) / static_cast<float>(bins));
            if (!(pos > cell.lo[k] && pos < cell.hi[k])) continue;
            sah.consider(pos, n_below, 0, n_above, best);
        }
    }
    return best;
}

// Splits the references by exact comparisons with the plane (the bins only
// chose it); straddlers are clipped to each child, in parallel for big nodes.
void partition_refs(const Config& c, const std::vector<Ref>& refs, const Split& s, const Box3f& cell_below,
                    const Box3f& cell_above, std::vector<Ref>& below, std::vector<Ref>& above) {
    const size_t n = refs.size();
    std::vector<uint8_t> side(n);
    auto classify = [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const float a = refs[i].box.lo[s.axis], b = refs[i].box.hi[s.axis];
            if (a == b && a == s.pos) side[i] = s.planar_below ? kBelow : kAbove;
            else if (b <= s.pos) side[i] = kBelow;
            else if (a >= s.pos) side[i] = kAbove;
            else side[i] = kBoth;
        }
    };
    std::vector<uint32_t> straddlers;
    if (n >= kParallelNodeRefs) parallel::for_range(size_t(0), n, size_t(8192), classify);
    else classify(0, n);
    for (size_t i = 0; i < n; ++i)
        if (side[i] == kBoth) straddlers.push_back(static_cast<uint32_t>(i));
    const size_t m = straddlers.size();
    std::vector<Box3f> part_below(m), part_above(m);
    std::vector<uint8_t> in_below(m), in_above(m);
    auto clip = [&](size_t lo, size_t hi) {
        for (size_t j = lo; j < hi; ++j) {
            const Ref& r = refs[straddlers[j]];
            in_below[j] = part_in(c, r.prim, r.box, cell_below, part_below[j]) ? 1 : 0;
            in_above[j] = part_in(c, r.prim, r.box, cell_above, part_above[j]) ? 1 : 0;
        }
    };
    if (n >= kParallelNodeRefs) parallel::for_range(size_t(0), m, size_t(1024), clip);
    else clip(0, m);
    size_t j = 0;
    for (size_t i = 0; i < n; ++i) {
        if (side[i] == kBelow) {
            below.push_back(refs[i]);
        } else if (side[i] == kAbove) {
            above.push_back(refs[i]);
        } else {
            if (in_below[j]) below.push_back({refs[i].prim, part_below[j]});
            if (in_above[j]) above.push_back({refs[i].prim, part_above[j]});
            ++j;
        }
    }
}

TempPtr build_binned(const Config& c, std::vector<Ref> refs, const Box3f& cell, int depth) {
    const size_t n = refs.size();
    if (n == 0 || depth >= c.max_depth) return make_leaf(prims_of(refs));
    if (n <= kKdExactSweepThreshold) return build_exact_from_refs(c, std::move(refs), cell, depth);
    const Split s = find_split_binned(c, refs, cell);
    // The bins see few planes: where none pays, the exact sweep decides.
    if (s.axis < 0 || !(s.cost < c.intersection_cost * static_cast<float>(n)))
        return build_exact_from_refs(c, std::move(refs), cell, depth);
    Box3f cell_below, cell_above;
    split_cells(cell, s, cell_below, cell_above);
    std::vector<Ref> below, above;
    partition_refs(c, refs, s, cell_below, cell_above, below, above);
    if (below.size() == n && above.size() == n) return build_exact_from_refs(c, std::move(refs), cell, depth);
    std::vector<Ref>().swap(refs);
    TempPtr below_tree, above_tree;
    build_both(
        n, [&] { below_tree = build_binned(c, std::move(below), cell_below, depth + 1); },
        [&] { above_tree = build_binned(c, std::move(above), cell_above, depth + 1); });
    return make_inner(s.axis, s.pos, std::move(below_tree), std::move(above_tree));
}

// ------------------------------------------------------------- layout ------

void count_tree(const TempNode& node, size_t& nodes, size_t& refs) {
    ++nodes;
    if (node.axis < 0) {
        refs += node.prims.size();
        return;
    }
    count_tree(*node.below, nodes, refs);
    count_tree(*node.above, nodes, refs);
}

// Depth-first; an inner node's two children take the next two free slots.
void lay_out(const TempNode& node, size_t slot, KdTree& tree) {
    if (node.axis < 0) {
        const size_t offset = tree.prim_indices.size();
        tree.prim_indices.insert(tree.prim_indices.end(), node.prims.begin(), node.prims.end());
        tree.nodes[slot] = KdNode::leaf(static_cast<uint32_t>(offset), static_cast<uint32_t>(node.prims.size()));
        return;
    }
    const size_t first = tree.nodes.size();
    tree.nodes.resize(first + 2);
    tree.nodes[slot] = KdNode::inner(node.axis, node.split, static_cast<uint32_t>(first));
    lay_out(*node.below, first, tree);
    lay_out(*node.above, first + 1, tree);
}

}  // namespace

KdTree build_kdtree(std::span<const Triangle> triangles, const SahCosts& sah, const BinnedSahOptions& binned,
                    const KdTreeOptions& kdtree) {
    KdTree tree;
    std::vector<Ref> refs;
    budgeted_reserve(refs, triangles.size(), "kd-tree references");
    Box3f bounds;
    for (size_t i = 0; i < triangles.size(); ++i) {
        const Triangle& t = triangles[i];
        // The same test that makes intersect_triangle reject zero-area triangles.
        const Vec3f normal = cross(t.v1 - t.v0, t.v2 - t.v0);
        if (normal.x == 0.0f && normal.y == 0.0f && normal.z == 0.0f) continue;
        const Box3f box = t.bounds();
        refs.push_back({static_cast<uint32_t>(i), box});
        bounds.extend(box);
    }
    if (refs.empty()) return tree;

    Config c;
    c.triangles = triangles.data();
    c.traversal_cost = sah.traversal;
    c.intersection_cost = sah.intersection;
    c.empty_factor = 1.0f - kdtree.empty_bonus;
    c.perfect_splits = kdtree.perfect_splits;
    c.max_depth = kdtree_max_depth(refs.size());
    c.bins = std::clamp(binned.bin_count, 2, kMaxBins);
    tree.bounds = bounds;
    tree.max_depth = c.max_depth;

    const TempPtr root = build_binned(c, std::move(refs), bounds, 0);

    size_t node_count = 0, ref_count = 0;
    count_tree(*root, node_count, ref_count);
    if (node_count > KdNode::kMaxIndex || ref_count > KdNode::kMaxIndex) {
        throw Error("kd-tree build: " + std::to_string(node_count) + " nodes and " + std::to_string(ref_count) +
                    " references exceed the 30-bit node offsets");
    }
    budgeted_reserve(tree.nodes, node_count, "kd-tree nodes");
    budgeted_reserve(tree.prim_indices, ref_count, "kd-tree references");
    tree.nodes.resize(1);
    lay_out(*root, 0, tree);
    return tree;
}

}  // namespace rf
