// `rayforge bench --animate`: per-frame acceleration maintenance over an
// animated scene (Garanzha 2014 ch. 2, Figs. 2.7-2.10; docs/animation.md). Per frame:
// Scene::set_time, SceneGeometry::update, then every update method's
// DynamicAccel::update timed, a full rebuild of the same frame with the same
// builder, and the Embree dynamic peer (refit, LOW and MEDIUM rebuilds) on
// the same vertex positions; the frame's ray sets (from the rebuilt tree)
// are traced by all of them. `--cluster-table` reproduces ch. 3's Table 3.1.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "bench_scenes.h"
#include "embree_peer.h"
#include "ray_sets.h"
#include "rayforge/accel/dynamic_accel.h"

namespace rf::bench {

// Frames first..last (inclusive; last < 0 = the animation's last) every `step`.
struct FrameRange {
    int first = 0;
    int last = -1;
    int step = 1;
};
// "A:B" or "A:B:S"; throws rf::Error.
FrameRange parse_frame_range(const std::string& text);
// The frames played: first..last, and with `backwards` then back to first and
// forward to last again (Garanzha 2014's 100 -> 1 -> 100). `frame_count` clamps last.
std::vector<int> frame_sequence(const FrameRange& range, int frame_count, bool backwards);

struct AnimateConfig {
    std::vector<UpdateMethod> methods{UpdateMethod::Refit, UpdateMethod::Adapt, UpdateMethod::Rebuild,
                                      UpdateMethod::Clusters, UpdateMethod::TwoLevel};
    Device device;                     // where the methods' worlds live (the rebuild and Embree: the CPU)
    BuildOptions build;                // builder and layout of every method and of the per-frame rebuild
    UpdateOptions update;              // adapt and cluster options (method is set per row)
    FrameRange frames;
    bool backwards = false;
    std::vector<RaySetKind> ray_sets{RaySetKind::Primary, RaySetKind::Shadow, RaySetKind::Diffuse};
    int width = 512, height = 384;     // the view of the primary and shadow sets
    size_t diffuse_rays = 1000000;     // the diffuse set cut or repeated to this many rays (0 = as generated)
    std::vector<EmbreeUpdate> embree{std::begin(kAllEmbreeUpdates), std::end(kAllEmbreeUpdates)};
    int threads = 0;                   // 0 = all cores
    int repetitions = 1;               // timed traces per set and frame (median)
    bool progress = true;
};

// One structure's traces of one frame's sets (ms, same order as the sets),
// and its hits' agreement with the rebuilt tree's (min over the sets).
struct FrameTraces {
    std::vector<double> trace_ms;
    double agreement = 1.0;
};

struct MethodFrame {
    bool ok = false;
    std::string error;        // why not, when !ok
    double update_ms = 0.0;   // the structure's update in World::set_time (UpdateStats::update_ms)
    UpdateStats stats;
    FrameTraces traces;
};

struct PeerFrame {
    bool ok = false;
    std::string error;
    double update_ms = 0.0;   // rtcCommitGeometry + rtcCommitScene (refit or rebuild)
    double copy_ms = 0.0;     // the positions copied into Embree's vertex buffer
    FrameTraces traces;
};

struct AnimateFrame {
    int frame = 0;
    float time = 0.0f;
    double scene_ms = 0.0;                // Scene::set_time + SceneGeometry::update
    double rebuild_ms = 0.0;              // rf::build_accel with the same options
    double rebuild_sah = 0.0;
    std::vector<size_t> rays;             // per set
    std::vector<double> rebuild_trace_ms; // per set
    std::vector<MethodFrame> methods;     // as AnimateResult::methods
    std::vector<PeerFrame> embree;        // as AnimateResult::embree
};

struct MethodColumn {
    UpdateMethod method = UpdateMethod::Refit;
    bool ok = false;
    std::string error;          // "n/a (reason)" when the method could not be built
    double initial_build_ms = 0.0;
};

struct PeerColumn {
    EmbreeUpdate update = EmbreeUpdate::Refit;
    bool ok = false;
    std::string error;
    double build_ms = 0.0;
};

struct AnimateResult {
    std::string scene;
    size_t triangles = 0;
    int frame_count = 0;        // of the animation
    int threads = 0;
    std::string build;          // "binned/bvh8"
    std::vector<RaySetKind> ray_sets;
    std::vector<MethodColumn> methods;
    std::vector<PeerColumn> embree;
    int build_frame = 0;        // the frame every structure was built at
    std::vector<AnimateFrame> frames;  // the frames after it, in play order
};

// Runs the animation of `scene` (loaded by load_bench_scene; its scene and
// geometry are evaluated in place). Throws rf::Error when the scene is not
// animated; a method or peer that fails is reported in its column instead.
AnimateResult run_animate_bench(LoadedScene& scene, const AnimateConfig& config, std::ostream& log);

// Per method: a per-frame table (update ms against the rebuild, SAH drift,
// Mrays/s of each set against the rebuilt tree's, adapt's counts); Embree's
// per-frame table; then the averages over the frames.
void print_animate_tables(std::ostream& out, const AnimateResult& result);
void write_animate_json(const std::string& path, const std::vector<AnimateResult>& results,
                        const std::string& command);

// --- ch. 3's Table 3.1 ---

struct ClusterTableConfig {
    std::vector<int> sizes{0, 10, 50, 100, 200};  // MaxCount = MaxSize; 0 = no clusters
    std::vector<ClusterHeuristic> heuristics{ClusterHeuristic::Acc, ClusterHeuristic::Naive};
    ClusterGeneration generation = ClusterGeneration::Merge;
    BuildOptions build;
    int width = 512, height = 384;
    int threads = 0;
    int repetitions = 3;       // builds and traces (median)
    bool progress = true;
    int subtree_size = 50;     // an extra Acc row with ClusterOptions::cluster_subtrees at this size (0: none)
};

struct ClusterRow {
    int size = 0;              // MaxCount = MaxSize (0: the triangle build)
    ClusterHeuristic heuristic = ClusterHeuristic::Acc;
    bool subtrees = false;     // ClusterOptions::cluster_subtrees
    bool ok = false;
    std::string error;
    double clustering_ms = 0.0;  // the one-time setup (clustering on frame 0's positions, subtrees): initial build - build_ms
    size_t clusters = 0;
    double build_ms = 0.0;       // the per-frame build (over cluster boxes, or triangles)
    double primary_ms = 0.0, diffuse_ms = 0.0;
    // Primary + diffuse trace time over the triangle build's, the median of
    // per-round ratios with the two traced alternately (1 for the triangle row).
    double trace_ratio = 1.0;
    // Work per diffuse ray (count_traversal): box tests and triangle tests.
    double steps_per_ray = 0.0, tests_per_ray = 0.0;
    double agreement = 1.0;      // hits against the triangle build's, min over both sets
};

struct ClusterTable {
    std::string scene;
    size_t triangles = 0, vertices = 0;
    size_t primary_rays = 0, diffuse_rays = 0;
    std::vector<ClusterRow> rows;
};

// A still scene is one frame; an animated one is measured at frame 0.
ClusterTable run_cluster_table(LoadedScene& scene, const ClusterTableConfig& config, std::ostream& log);
void print_cluster_tables(std::ostream& out, const std::vector<ClusterTable>& tables, int threads);

}  // namespace rf::bench
