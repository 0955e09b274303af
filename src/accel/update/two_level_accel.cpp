// The two-level structure for animated scenes (instancing in the manner of
// Wald, Benthin and Slusallek 2003, "Distributed Interactive Ray Tracing of
// Dynamic Scenes"; the two-level method of docs/animation.md): one bottom-level BVH
// per mesh in the mesh's object space, and a top-level BVH over the world
// boxes of the visible instances, rebuilt every frame.
//
// Data layout: per mesh (referenced by any instance) its object-space
// triangles, the canonical BVH built over them with BuildOptions::builder,
// and for BVH4/BVH8 the wide layout collapsed from it (traced with the SIMD
// single-ray traversal of backend/cpu/wide_bvh_traversal.h; BVH2 is traced
// by trace/bvh_traversal.h). Per visible instance a TwoLevelInstance (the
// inverse transform, its mesh's structure, its first flat triangle). The
// top level is a canonical binary BVH built by the binned SAH builder over
// one stand-in triangle per instance whose bounds are the instance's world
// box (the BLAS root box through Instance::transform, padded by a few ulps
// of its magnitude) and whose centroid is the box centre; leaves hold one
// instance. BVH2 traces it as is (trace/two_level_traversal.h, the RF_HD
// path a kernel takes); BVH4/BVH8 collapse it into 8-wide nodes traced with
// the SIMD slab test, and both call the same per-leaf instance step.
//
// Per frame (update): the meshes GeometryChange::meshes names are refitted
// (their object-space triangles re-read, boxes recomputed bottom-up, the
// topology kept) and their wide layout re-collapsed (the packs copy the
// vertices, so they must be rewritten anyway); rigid motion and visibility
// touch only the top level, which is rebuilt from every instance's current
// transform. UpdateStats::sah_cost is the combined cost: the top level's
// inner nodes plus, per instance, its world box's share of the top root's
// area times its mesh's (object-space, root-normalised) SAH cost.
//
// Parallelism: bottom levels are built and refitted in parallel over meshes
// (each build is itself parallel); the top level is one binned build.
// Determinism: every build is deterministic for any thread count, and so
// is the result.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <string>
#include <vector>

#include "accel/bvh/builders/binned_sah.h"
#include "accel/bvh/builders/build_bvh.h"
#include "accel/bvh/layout/wide_bvh.h"
#include "accel/update/bvh_updater.h"
#include "accel/update/two_level_accel.h"
#include "core/parallel.h"
#include "backend/cpu/ray_batches.h"
#include "backend/cpu/wide_bvh_traversal.h"
#include "rayforge/core/error.h"
#include "trace/two_level_traversal.h"

namespace rf {
namespace {

using Clock = std::chrono::steady_clock;
constexpr float kInf = std::numeric_limits<float>::infinity();

double ms_since(Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The bottom-level traversal of the wide layouts, in the shape
// trace/two_level_traversal.h asks for.
template <int N>
struct WideBlas {
    Hit intersect(const WideBvhView<N>& bvh, const Ray& ray) const { return wide_bvh_intersect(bvh, ray); }
    bool occluded(const WideBvhView<N>& bvh, const Ray& ray) const { return wide_bvh_occluded(bvh, ray); }
};

// Per layout: the view and trace of a bottom level (N = 2: binary).
template <int N>
struct BlasLayout {
    using View = WideBvhView<N>;
    using Trace = WideBlas<N>;
    using Wide = WideBvh<N>;
};
template <>
struct BlasLayout<2> {
    using View = BvhView;
    using Trace = Bvh2Blas;
    struct Wide {};
};

void object_triangles(const Mesh& mesh, std::vector<Triangle>& out) {
    out.resize(mesh.triangle_count());
    for (size_t t = 0; t < out.size(); ++t) {
        const uint32_t* idx = &mesh.indices[3 * t];
        out[t] = Triangle{mesh.positions[idx[0]], mesh.positions[idx[1]], mesh.positions[idx[2]]};
    }
}

// Boxes recomputed bottom-up: in the canonical depth-first order every
// child lies after its parent, so one backward sweep suffices.
void refit(Bvh& bvh, const std::vector<Triangle>& triangles) {
    for (size_t i = bvh.nodes.size(); i-- > 0;) {
        BvhNode& node = bvh.nodes[i];
        Box3f box;
        if (node.is_leaf()) {
            for (uint32_t s = node.first; s < node.first + node.count; ++s)
                box.extend(triangles[bvh.prim_indices[s]].bounds());
        } else {
            box = merge(bvh.nodes[node.first].bounds, bvh.nodes[node.first + 1].bounds);
        }
        node.bounds = box;
    }
}

// One mesh's bottom level.
template <int N>
struct Blas {
    std::vector<Triangle> triangles;  // object space
    Bvh bvh;
    typename BlasLayout<N>::Wide wide;
    double sah_cost = 0.0;

    void relayout() {
        sah_cost = bvh.nodes.empty() ? 0.0 : bvh.sah_cost(1.0f, 1.0f);
        if constexpr (N != 2) wide = bvh.nodes.empty() ? typename BlasLayout<N>::Wide{} : collapse_bvh<N>(bvh, triangles);
    }
    [[nodiscard]] typename BlasLayout<N>::View view() const {
        if constexpr (N == 2) {
            return BvhView{bvh.nodes.data(), bvh.prim_indices.data(), triangles.data(), uint32_t(bvh.nodes.size())};
        } else {
            return WideBvhView<N>{wide.nodes.data(), wide.packs.data(), uint32_t(wide.nodes.size()), wide.coord_scale};
        }
    }
    [[nodiscard]] size_t node_count() const {
        if constexpr (N == 2) return bvh.nodes.size();
        else return wide.nodes.size();
    }
    [[nodiscard]] size_t bytes() const {
        size_t b = bvh.memory_bytes() + triangles.size() * sizeof(Triangle);
        if constexpr (N != 2) b += wide.memory_bytes();
        return b;
    }
};

// The instance's world box, padded so that rounding in the transforms (of
// the box here, of the ray into object space) never culls a hit.
Box3f padded_world_box(const Affine3f& transform, const Box3f& object_box) {
    Box3f box = transform.transform_box(object_box);
    const float magnitude = max_component(max(abs(box.lo), abs(box.hi)));
    const Vec3f pad(magnitude * 0x1p-18f + std::numeric_limits<float>::min());
    return Box3f{box.lo - pad, box.hi + pad};
}

// The top level in 8-wide nodes for the SIMD layouts: each binary node's
// slots are expanded, largest area first, until 8 are filled; a slot is a
// wide node or (kWideLeafFlag | binary leaf index), its instances named by
// the binary leaf. Traced with the SIMD slab test of wide_bvh_traversal.h.
struct WideTop {
    std::vector<WideNode<8>> nodes;  // empty: every ray misses
    float coord_scale = 1.0f;
};

uint32_t collapse_top_node(const Bvh& top, uint32_t binary, WideTop& out) {
    uint32_t slots[8];
    int count = 0;
    if (top.nodes[binary].is_leaf()) {
        slots[count++] = binary;
    } else {
        slots[count++] = top.nodes[binary].first;
        slots[count++] = top.nodes[binary].first + 1;
    }
    while (count < 8) {
        int widest = -1;
        for (int i = 0; i < count; ++i) {
            const BvhNode& n = top.nodes[slots[i]];
            if (!n.is_leaf() && (widest < 0 || n.bounds.surface_area() > top.nodes[slots[widest]].bounds.surface_area()))
                widest = i;
        }
        if (widest < 0) break;
        const uint32_t first = top.nodes[slots[widest]].first;
        slots[widest] = first;
        slots[count++] = first + 1;
    }
    const auto index = uint32_t(out.nodes.size());
    out.nodes.emplace_back();
    for (int c = 0; c < 8; ++c) {
        const Box3f box = c < count ? top.nodes[slots[c]].bounds : Box3f{Vec3f(kInf), Vec3f(-kInf)};
        for (int axis = 0; axis < 3; ++axis) {
            out.nodes[index].bounds[2 * axis][c] = box.lo[axis];
            out.nodes[index].bounds[2 * axis + 1][c] = box.hi[axis];
        }
        uint32_t ref = kWideEmptyRef;
        if (c < count) ref = top.nodes[slots[c]].is_leaf() ? (kWideLeafFlag | slots[c]) : collapse_top_node(top, slots[c], out);
        out.nodes[index].child[c] = ref;  // after the recursion: it may move the array
    }
    return index;
}

void collapse_top(const Bvh& top, WideTop& out) {
    out.nodes.clear();
    if (top.nodes.empty()) return;
    const Box3f& root = top.nodes[0].bounds;
    out.coord_scale = max_component(max(abs(root.lo), abs(root.hi)));
    collapse_top_node(top, 0, out);
}

// Nearest hit child first; the others wait on the stack with their entry
// distance and are dropped once a closer hit is known.
template <bool kAnyHit, class View, class Trace>
Hit traverse_wide_top(const WideTop& top, const TwoLevelView<View>& view, const Ray& ray, const Trace& trace) {
    using namespace simd;
    Hit hit;
    if (top.nodes.empty()) return hit;
    const wide_detail::BoxRay<8> box_ray = wide_detail::BoxRay<8>::make(ray, top.coord_scale);
    const vfloat<8> tmin_v = set1<8>(ray.tmin);
    float tmax = ray.tmax;
    float tmax_far = detail::widen_far(tmax);
    vfloat<8> tmax_far_v = set1<8>(tmax_far);
    wide_detail::StackItem stack[wide_detail::kStackSize<8>];
    int size = 0;
    uint32_t ref = 0;
    for (;;) {
        if (!wide_is_leaf(ref)) {
            const WideNode<8>& node = top.nodes[ref];
            vfloat<8> near_v;
            unsigned mask = wide_detail::box_hits(node, box_ray, tmin_v, tmax_far_v, near_v);
            alignas(32) float near[8];
            store<8>(near, near_v);
            // Push the hit children farthest first (insertion into the stack's top).
            const int base = size;
            for (; mask; mask &= mask - 1) {
                const int c = first_bit(mask);
                int at = size++;
                while (at > base && stack[at - 1].dist < near[c]) {
                    stack[at] = stack[at - 1];
                    --at;
                }
                stack[at] = {node.child[c], near[c]};
            }
        } else {
            if (detail::two_level_leaf<kAnyHit>(view, view.top_nodes[ref & ~kWideLeafFlag], ray, trace, tmax, hit))
                return hit;
            tmax_far = detail::widen_far(tmax);
            tmax_far_v = set1<8>(tmax_far);
        }
        for (;;) {
            if (size == 0) return hit;
            const wide_detail::StackItem item = stack[--size];
            if (item.dist <= tmax_far) {
                ref = item.ref;
                break;
            }
        }
    }
}

template <int N>
class TwoLevelAccel final : public TwoLevelHost {
public:
    TwoLevelAccel(const Scene& scene, const SceneGeometry& geometry, const BuildOptions& build)
        : scene_(scene), geometry_(geometry), build_(build), blas_(scene.meshes.size()),
          views_(scene.meshes.size()), used_(scene.meshes.size(), 0) {
        if (geometry.instance_first_triangle.size() != scene.instances.size() + 1)
            throw Error("two-level accel: the geometry was not built from this scene");
        const auto start = Clock::now();
        std::vector<uint32_t> used;
        for (const Instance& inst : scene.instances) used.push_back(inst.mesh);
        std::sort(used.begin(), used.end());
        used.erase(std::unique(used.begin(), used.end()), used.end());
        for (uint32_t m : used) used_[m] = 1;
        parallel::with_threads(build.threads, [&] {
            parallel::for_range(size_t(0), used.size(), size_t(1), [&](size_t lo, size_t hi) {
                for (size_t i = lo; i != hi; ++i) build_blas(used[i]);
            });
            return 0;
        });
        rebuild_top();
        build_ms_ = ms_since(start);
    }

    [[nodiscard]] Hit intersect(const Ray& ray) const override {
        if constexpr (N == 2) return two_level_intersect(view_, ray, typename BlasLayout<N>::Trace{});
        else return traverse_wide_top<false>(wide_top_, view_, ray, typename BlasLayout<N>::Trace{});
    }
    [[nodiscard]] bool occluded(const Ray& ray) const override {
        if constexpr (N == 2) return two_level_occluded(view_, ray, typename BlasLayout<N>::Trace{});
        else return traverse_wide_top<true>(wide_top_, view_, ray, typename BlasLayout<N>::Trace{}).found();
    }
    void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override {
        check_batch_sizes("two-level intersect", rays.size(), hits.size());
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            for (size_t i = lo; i != hi; ++i) hits[i] = TwoLevelAccel::intersect(rays[i]);
        });
    }
    void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const override {
        check_batch_sizes("two-level occluded", rays.size(), occluded.size());
        parallel::for_range(size_t(0), rays.size(), kRayGrainSize, [&](size_t lo, size_t hi) {
            for (size_t i = lo; i != hi; ++i) occluded[i] = TwoLevelAccel::occluded(rays[i]) ? 1 : 0;
        });
    }

    UpdateStats update(const GeometryChange& change) override {
        const auto start = Clock::now();
        std::vector<uint32_t> meshes = change.meshes;
        std::sort(meshes.begin(), meshes.end());
        meshes.erase(std::unique(meshes.begin(), meshes.end()), meshes.end());
        for (uint32_t m : meshes) {
            if (m >= scene_.meshes.size())
                throw Error("two-level update: mesh " + std::to_string(m) + " does not exist");
        }
        // Meshes no instance uses have no bottom level to update.
        std::erase_if(meshes, [&](uint32_t m) { return !used_[m]; });
        for (uint32_t m : meshes) {
            if (scene_.meshes[m].triangle_count() != blas_[m].triangles.size())
                throw Error("two-level update: mesh " + std::to_string(m) + " changed its triangle count");
        }
        if (scene_.instances.size() + 1 != geometry_.instance_first_triangle.size() ||
            scene_.meshes.size() != blas_.size())
            throw Error("two-level update: the scene's instances or meshes changed in number");
        UpdateStats stats;
        parallel::with_threads(build_.threads, [&] {
            parallel::for_range(size_t(0), meshes.size(), size_t(1), [&](size_t lo, size_t hi) {
                for (size_t i = lo; i != hi; ++i) refit_blas(meshes[i]);
            });
            return 0;
        });
        stats.layout_ms = layout_ms_;  // summed by refit_blas
        layout_ms_ = 0.0;
        stats.meshes_updated = meshes.size();
        updated_ = std::move(meshes);
        rebuild_top();
        stats.sah_cost = sah_cost_;
        stats.update_ms = ms_since(start);
        return stats;
    }

    [[nodiscard]] UpdateMethod method() const override { return UpdateMethod::TwoLevel; }
    [[nodiscard]] double initial_build_ms() const override { return build_ms_; }

    [[nodiscard]] AccelStats stats() const override {
        AccelStats s;
        s.name = "two-level/" + to_string(build_.builder) + "/" + to_string(build_.layout);
        s.build_ms = build_ms_;
        s.node_count = N == 2 ? top_.nodes.size() : wide_top_.nodes.size();
        s.leaf_count = top_.leaf_count();
        s.bytes = top_.memory_bytes() + wide_top_.nodes.size() * sizeof(WideNode<8>) + instances_.size() * sizeof(TwoLevelInstance) +
                  views_.size() * sizeof(typename BlasLayout<N>::View);
        for (const Blas<N>& b : blas_) {
            s.node_count += b.node_count();
            s.leaf_count += b.bvh.nodes.empty() ? 0 : b.bvh.leaf_count();
            s.bytes += b.bytes();
        }
        s.sah_cost = sah_cost_;
        s.quality_cost = std::numeric_limits<double>::quiet_NaN();
        return s;
    }

    [[nodiscard]] size_t mesh_count() const override { return blas_.size(); }
    [[nodiscard]] const Bvh& blas(uint32_t mesh) const override { return blas_.at(mesh).bvh; }
    [[nodiscard]] std::span<const Triangle> blas_triangles(uint32_t mesh) const override {
        return blas_.at(mesh).triangles;
    }
    [[nodiscard]] std::span<const uint32_t> updated_meshes() const override { return updated_; }
    [[nodiscard]] const Bvh& top() const override { return top_; }
    [[nodiscard]] std::span<const TwoLevelInstance> instances() const override { return instances_; }

private:
    void build_blas(uint32_t mesh) {
        Blas<N>& b = blas_[mesh];
        object_triangles(scene_.meshes[mesh], b.triangles);
        if (!b.triangles.empty()) b.bvh = build_bvh_on_cpu(b.triangles, build_);
        b.relayout();
        views_[mesh] = b.view();
    }

    void refit_blas(uint32_t mesh) {
        Blas<N>& b = blas_[mesh];
        object_triangles(scene_.meshes[mesh], b.triangles);
        refit(b.bvh, b.triangles);
        const auto start = Clock::now();
        b.relayout();
        views_[mesh] = b.view();
        add_layout_ms(ms_since(start));
    }
    void add_layout_ms(double ms) {
        std::lock_guard<std::mutex> lock(layout_mutex_);
        layout_ms_ += ms;
    }

    // The visible instances of non-empty meshes with invertible transforms
    // (a singular one flattens its triangles to zero area: never hit).
    void rebuild_top() {
        instances_.clear();
        std::vector<Triangle> boxes;
        std::vector<double> blas_cost;
        for (uint32_t i = 0; i < scene_.instances.size(); ++i) {
            const Instance& inst = scene_.instances[i];
            const Blas<N>& b = blas_[inst.mesh];
            if (!inst.visible || b.bvh.nodes.empty()) continue;
            Affine3f inverse;
            try {
                inverse = inst.transform.inverse();
            } catch (const Error&) {
                continue;
            }
            const Box3f box = padded_world_box(inst.transform, b.bvh.nodes[0].bounds);
            instances_.push_back({inverse, inst.mesh, geometry_.instance_first_triangle[i]});
            boxes.push_back(Triangle{box.lo, box.hi, box.center()});
            blas_cost.push_back(b.sah_cost);
        }
        top_ = build_binned_sah(boxes, BvhBuildConfig{1, build_.sah, nullptr}, build_.binned);
        view_ = TwoLevelView<typename BlasLayout<N>::View>{top_.nodes.data(), top_.prim_indices.data(),
                                                           uint32_t(top_.nodes.size()), instances_.data(),
                                                           views_.data()};
        sah_cost_ = combined_sah(boxes, blas_cost);
        if constexpr (N != 2) collapse_top(top_, wide_top_);
    }

    // Top inner nodes (C_trav = 1) plus each instance's bottom level, weighted
    // by its world box's share of the top root's area.
    [[nodiscard]] double combined_sah(const std::vector<Triangle>& boxes, const std::vector<double>& blas_cost) const {
        if (top_.nodes.empty()) return 0.0;
        const double root_area = top_.nodes[0].bounds.surface_area();
        if (!(root_area > 0.0)) return top_.sah_cost(1.0f, 1.0f);
        double cost = top_.sah_cost(1.0f, 0.0f);
        for (size_t i = 0; i < boxes.size(); ++i)
            cost += double(boxes[i].bounds().surface_area()) / root_area * blas_cost[i];
        return cost;
    }

    const Scene& scene_;
    const SceneGeometry& geometry_;
    BuildOptions build_;
    std::vector<Blas<N>> blas_;                         // per mesh (empty where no instance uses it)
    std::vector<typename BlasLayout<N>::View> views_;  // per mesh
    std::vector<uint8_t> used_;                         // per mesh: some instance uses it
    std::vector<TwoLevelInstance> instances_;          // the visible ones
    std::vector<uint32_t> updated_;                     // the meshes the last update refitted
    Bvh top_;
    WideTop wide_top_;  // the SIMD layouts' top level (N > 2)
    TwoLevelView<typename BlasLayout<N>::View> view_;
    double build_ms_ = 0.0;
    double sah_cost_ = 0.0;
    double layout_ms_ = 0.0;
    std::mutex layout_mutex_;
};

}  // namespace

std::unique_ptr<TwoLevelHost> make_two_level_host(const Scene& scene, const SceneGeometry& geometry,
                                                  const BuildOptions& build) {
    BuildOptions host = build;
    host.device = Device{};
    host.layout = Layout::Bvh2;
    validate_build_options(host);
    return std::make_unique<TwoLevelAccel<2>>(scene, geometry, host);
}

std::unique_ptr<DynamicAccel> make_two_level_accel(const Scene& scene, const SceneGeometry& geometry,
                                                   const BuildOptions& build) {
    validate_build_options(build);
    if (build.structure != Structure::Bvh) throw Error("two-level accel: the structure must be bvh");
    if (build.device.is_cuda())
        throw Error("two-level accel: this is the CPU version; build_dynamic_accel makes the device one");
    switch (build.layout) {
        case Layout::Bvh2: return std::make_unique<TwoLevelAccel<2>>(scene, geometry, build);
        case Layout::Bvh4: return std::make_unique<TwoLevelAccel<4>>(scene, geometry, build);
        case Layout::Bvh8: return std::make_unique<TwoLevelAccel<8>>(scene, geometry, build);
    }
    throw Error("two-level accel: unknown layout");
}

}  // namespace rf
