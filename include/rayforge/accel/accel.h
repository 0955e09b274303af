// The one interface every acceleration structure answers ray queries through.
// Integrators and the bench only see Accel; they never know which structure
// (or builder, or layout) is behind it.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "rayforge/accel/build_report.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/backend/device.h"
#include "rayforge/core/progress.h"
#include "rayforge/math/ray.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

enum class Structure : uint8_t {
    Bvh,            // binary BVH from one of the builders below, traced in one of the layouts
    Grid,           // uniform grid, 3D-DDA (Amanatides and Woo 1987)
    ProximityGrid,  // uniform grid with proximity clouds (after Karlsson and Ljungstedt 2004)
    KdTree,         // SAH kd-tree (Wald and Havran 2006)
    BruteForce,     // every triangle for every ray: the reference
};

// BVH builders; every one produces the canonical rf::Bvh.
enum class Builder : uint8_t {
    BinnedSah,     // Wald 2007
    SweepSah,      // full sweep over sorted centroids
    Sbvh,          // Stich et al. 2009, spatial splits
    Lbvh30,        // Karras 2012, 30-bit Morton codes
    Lbvh63,        // Karras 2012, 63-bit Morton codes
    Hlbvh2,        // Garanzha 2014, ch. 5
    GridBvh,       // Garanzha 2014, ch. 4
    GridBvhSplit,  // Garanzha 2014, ch. 4, with partial triangles
    Ploc,          // Meister and Bittner 2018
    Hploc,         // Benthin et al. 2024, hierarchical PLOC (radius: PlocOptions)
};

// How a BVH is laid out for tracing: the canonical binary nodes, or 4/8-wide
// nodes collapsed from it by SAH and traced with SIMD box tests.
enum class Layout : uint8_t { Bvh2, Bvh4, Bvh8 };

// kd-tree traversal algorithms: a full stack; a short stack (Horn et al.
// 2007); kd-restart (Foley and Sugerman 2005); kd-restart with push-down
// (Horn et al. 2007).
enum class KdTraversal : uint8_t { Stack, ShortStack, Restart, Pushdown };

// The SAH's costs: every SAH decision (BVH builders, leaf collapse, kd-tree, optimizer).
struct SahCosts {
    float traversal = 1.0f;     // C_trav
    float intersection = 1.0f;  // C_int
};
// Binned builders (binned SAH; the kd-tree's binned upper levels).
struct BinnedSahOptions {
    int bin_count = 16;  // SAH bins per axis
};
// SBVH: spatial splits are tried where the overlap of the best object split
// exceeds alpha times the root's area (Stich et al. 2009).
struct SbvhOptions {
    float alpha = 1e-5f;
};
// PLOC and H-PLOC: nearest-neighbour search radius along the Morton curve
// (H-PLOC clamps it to 31: a range's clusters fit one 32-lane warp).
struct PlocOptions {
    int radius = 16;
};
// GridBvhSplit's partial triangles.
struct GridBvhOptions {
    float split_budget = 0.3f;  // partial-triangle budget as a fraction of the triangle count
};
// Post-build optimizer for any BVH builder (reinsertion, Meister and Bittner 2018).
struct ReinsertionOptions {
    bool enabled = false;
    int iterations = 0;  // 0 = the optimizer's default
};
// Post-build optimizer for any BVH builder (treelet restructuring, Karras and
// Aila 2013): treelets of up to treelet_leaves leaves re-linked to their
// SAH-optimal topology, bottom up, in `rounds` rounds.
struct TreeletOptions {
    bool enabled = false;
    int treelet_leaves = 7;  // the paper's n, 3 .. 7
    int rounds = 3;          // 1 .. 16; round r restructures subtrees of at least treelet_leaves * 2^r primitives
};
// Uniform grids.
struct UniformGridOptions {
    // Cells on the longest axis; 0 = automatic: 4 * n^(1/4) cells on the
    // shortest axis (after Purcell), cubic cells.
    int resolution = 0;
};
struct KdTreeOptions {
    KdTraversal traversal = KdTraversal::Stack;
    bool perfect_splits = true;   // clip triangles to the cell when evaluating splits
    float empty_bonus = 0.2f;     // SAH discount for cutting off empty space
    int short_stack_size = 4;     // entries of the short-stack traversal
};

struct BuildOptions {
    Structure structure = Structure::Bvh;
    Builder builder = Builder::BinnedSah;
    Layout layout = Layout::Bvh8;  // the fastest traversal measured (docs/benchmarks.md)
    Device device;                 // where to build and trace: cpu (default), cuda, cuda:N
    GpuKernel gpu_kernel = kDefaultGpuKernel;  // on a CUDA device: the traversal kernel, which picks the
                                               // structure (and layout) built; `layout` is for the CPU
    int threads = 0;               // 0 = all cores
    int max_leaf_size = 4;         // every BVH builder: leaves never hold more primitives than this
    SahCosts sah;
    BinnedSahOptions binned;
    SbvhOptions sbvh;
    PlocOptions ploc;
    GridBvhOptions grid_bvh;
    ReinsertionOptions reinsertion;
    TreeletOptions treelets;
    UniformGridOptions grid;
    KdTreeOptions kdtree;
    // CUDA backend only: build on the device where a device builder exists
    // (lbvh30, lbvh63, hlbvh2, ploc, hploc, gridbvh, gridbvh-split, uniform grids)
    // and convert to the GPU layouts there; false builds on the CPU. Every
    // device builder yields the same structure as its CPU version.
    bool build_on_device = true;
};

struct AccelStats {
    std::string name;            // e.g. "bvh/binned"
    double build_ms = 0.0;       // triangles in memory -> traversable, layout conversion included
    double layout_ms = 0.0;      // the layout conversion alone (0 when traced in the built form)
    size_t node_count = 0;
    size_t leaf_count = 0;
    size_t bytes = 0;            // structure memory, excluding the triangles
    size_t device_bytes = 0;     // on a CUDA device: the device memory it holds, triangles included
    // Tree quality; NaN where the metric does not apply (e.g. brute force).
    double sah_cost = 0.0;       // C_trav = C_int = 1, normalised by root area
    double quality_cost = 0.0;   // Garanzha's formula 4.2, C(root) with nc = 2 (quality = 1 / C)
};

// Work done by traversals, summed over rays (the instrumented pass of the bench).
struct TraversalTotals {
    uint64_t rays = 0;
    uint64_t steps = 0;        // node visits (box tests) in trees, cells visited in grids
    uint64_t prim_tests = 0;   // ray-triangle tests
    uint64_t restarts = 0;     // kd-tree restarts (0 elsewhere)
    uint64_t node_fetches = 0; // BVH nodes fetched, whatever their width (0 for kd-trees and grids)
    TraversalTotals& operator+=(const TraversalTotals& o) {
        rays += o.rays;
        steps += o.steps;
        prim_tests += o.prim_tests;
        restarts += o.restarts;
        node_fetches += o.node_fetches;
        return *this;
    }
};

class Accel {
public:
    virtual ~Accel() = default;
    // Closest hit with t in [ray.tmin, ray.tmax]; Hit::found() is false on a miss.
    [[nodiscard]] virtual Hit intersect(const Ray& ray) const = 0;
    // Any hit with t in [ray.tmin, ray.tmax].
    [[nodiscard]] virtual bool occluded(const Ray& ray) const = 0;
    // Batches (parallel over rays); hits.size() == rays.size().
    virtual void intersect(std::span<const Ray> rays, std::span<Hit> hits) const;
    virtual void occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) const;
    // Batches whose rays and answers live in the memory of the accel's CUDA
    // device (cudaMalloc'd, managed, or a DLPack / __cuda_array_interface__
    // array's pointer): traced on `stream` (a cudaStream_t; nullptr: the
    // default stream) without a copy through the host; returns once the
    // answers are written. Concurrent calls are safe: each call has its own
    // scratch. Throws rf::Error for an accel on the CPU (use the span
    // batches) and for pointers that are not memory of the accel's device.
    virtual void intersect_on_device(const Ray* rays, Hit* hits, size_t count, void* stream = nullptr) const;
    virtual void occluded_on_device(const Ray* rays, uint8_t* occluded, size_t count, void* stream = nullptr) const;
    [[nodiscard]] virtual AccelStats stats() const = 0;
    // Where the structure lives and its queries run: the CPU, or a CUDA device.
    [[nodiscard]] virtual Device device() const { return {}; }
    // How it was built (a CPU build reports no stages).
    [[nodiscard]] virtual BuildReport build_report() const;
    // Instrumented traversal of every ray (closest hit, or any hit), adding
    // its work to `totals`; false when the structure keeps no counters.
    virtual bool count_traversal(std::span<const Ray> rays, bool any_hit, TraversalTotals& totals) const;
    // The traversal alone, timed (the bench): `rays` kept where the structure
    // lives (device memory for a CUDA accel), one warm-up trace, then `runs`
    // timed traces; returns each run's milliseconds (CUDA events around the
    // launch on a device, wall time on the CPU) and leaves the last run's
    // answers in `hits` (closest hit) or `occluded` (any hit), one per ray.
    virtual std::vector<double> time_traversal(std::span<const Ray> rays, bool any_hit, int runs,
                                               std::span<Hit> hits, std::span<uint8_t> occluded) const;
};

// Builds the structure named in `options` over `geometry`, which must outlive
// the result, on options.device: the CPU, or a CUDA device (where the
// structure is built on the device when options.build_on_device is set and
// the builder has a device version, and is traced by options.gpu_kernel;
// batches of host rays are then copied there and back). `progress` sees
// the fraction done, 0 first and 1 last: in between, a CPU BVH from the
// binned, sweep or SBVH builder reports the references placed in leaves
// (up to 0.9, the layout conversion being the rest); other structures and
// devices report only 0 and 1. It is called on the building thread. Throws
// rf::Error for invalid options or a device that cannot be used.
std::unique_ptr<Accel> build_accel(const SceneGeometry& geometry, const BuildOptions& options = {},
                                   const ProgressCallback& progress = {});

// The canonical BVH of options.builder over `triangles` (the reinsertion
// optimizer after it when asked), on options.device: a CUDA device runs the
// builder's device version (lbvh30, lbvh63, hlbvh2, ploc, hploc, gridbvh,
// gridbvh-split have one; rf::Error for the others) and gives the same BVH.
// `report`, when given, gets the build's stages.
Bvh build_bvh(std::span<const Triangle> triangles, const BuildOptions& options, BuildReport* report = nullptr);

// The structure a GPU kernel traverses: bvh (bvh2, aila-laine, cwbvh),
// kdtree (kd-short-stack, kd-restart), grid, grid-proximity. On a CUDA device
// BuildOptions::structure must be the one of BuildOptions::gpu_kernel.
Structure structure_of(GpuKernel kernel);

// Throws rf::Error naming the first option out of its range (build_accel and
// build_bvh call it).
void validate_build_options(const BuildOptions& options);

// Names for the CLI, the bench and scene files; parse_* throw rf::Error when unknown.
//   structures: bvh, grid, grid-proximity, kdtree, brute
//   builders:   binned, sweep, sbvh, lbvh30, lbvh63 (lbvh = lbvh30), hlbvh2, gridbvh, gridbvh-split, ploc,
//               hploc
//   layouts:    bvh2, bvh4, bvh8
//   kd-tree traversals: stack, short-stack, restart, pushdown
Structure parse_structure(const std::string& name);
Builder parse_builder(const std::string& name);
Layout parse_layout(const std::string& name);
KdTraversal parse_kd_traversal(const std::string& name);
std::string to_string(Structure structure);
std::string to_string(Builder builder);
std::string to_string(Layout layout);
std::string to_string(KdTraversal traversal);

}  // namespace rf
