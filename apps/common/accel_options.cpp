#include "accel_options.h"

#include <cstdio>

#include "rayforge/core/error.h"

namespace rf::cli {

void add_accel_options(CLI::App* cmd, AccelArgs& a) {
    const BuildOptions defaults;
    const std::string group = "Acceleration structure";
    cmd->add_option("--accel", a.accel,
                    "Structure: bvh | grid | grid-proximity | kdtree | brute (default " +
                        to_string(defaults.structure) + ")")
        ->group(group);
    cmd->add_option("--builder", a.builder,
                    "BVH builder: binned | sweep | sbvh | lbvh30 | lbvh63 | hlbvh2 | gridbvh | gridbvh-split | ploc "
                    "(default " + to_string(defaults.builder) + ")")
        ->group(group);
    cmd->add_option("--layout", a.layout,
                    "BVH layout traced: bvh2 | bvh4 | bvh8 (default " + to_string(defaults.layout) + ")")
        ->group(group);
    cmd->add_flag("--optimize", a.options.reinsertion.enabled, "Optimise the BVH by reinsertion after building")
        ->group(group);
    cmd->add_option("--optimize-iterations", a.options.reinsertion.iterations,
                    "Reinsertion rounds (default 0 = until it stops improving)")
        ->check(CLI::Range(0, 1000))
        ->group(group);
    cmd->add_option("--bins", a.options.binned.bin_count, "SAH bins per axis of binned builders (default 16)")
        ->check(CLI::Range(2, 256))
        ->group(group);
    cmd->add_option("--leaf-size", a.options.max_leaf_size, "Most triangles per BVH leaf (default 4)")
        ->check(CLI::Range(1, 64))
        ->group(group);
    cmd->add_option("--sbvh-alpha", a.options.sbvh.alpha,
                    "SBVH: try spatial splits above this overlap / root area (default 1e-5)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--ploc-radius", a.options.ploc.radius, "PLOC nearest-neighbour search radius (default 16)")
        ->check(CLI::Range(1, 256))
        ->group(group);
    cmd->add_option("--split-budget", a.options.grid_bvh.split_budget,
                    "GridBvhSplit: partial triangles as a fraction of the triangle count (default 0.3)")
        ->check(CLI::Range(0.0f, 4.0f))
        ->group(group);
    cmd->add_option("--grid-res", a.options.grid.resolution,
                    "Grids: cells on the longest axis (default 0 = 4 n^(1/4) on the shortest axis, cubic cells)")
        ->check(CLI::Range(0, 2048))
        ->group(group);
    cmd->add_option("--kd-traversal", a.kd_traversal,
                    "kd-tree traversal: stack | short-stack | restart | pushdown (default stack)")
        ->group(group);
}

void add_update_options(CLI::App* cmd, AccelArgs& a) {
    const std::string group = "Animation: acceleration-structure updates";
    cmd->add_option("--update", a.update_method,
                    "How the structure follows an animation: refit | adapt (Garanzha 2014 ch. 2: refit, local "
                    "rebuilds, migrations) | rebuild | clusters (ch. 3: builds over precomputed clusters) | "
                    "two-level (a BVH per mesh, a top level over instances); on --device cuda refit, rebuild "
                    "and two-level (default: the scene's, else " +
                        to_string(kDefaultUpdateMethod) + ")")
        ->group(group);
    cmd->add_option("--adapt-reading", a.adapt_reading,
                    "adapt: the text's two readings of its swapped thresholds: stated (dM 0.05, dE 0.01; the "
                    "default) | closing (dM 0.01, dE 0.05)")
        ->group(group);
    cmd->add_option("--adapt-dm", a.adapt_dm, "adapt: dM, migrating when SAH/saved SAH < 1 - dM (overrides the reading)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--adapt-de", a.adapt_de, "adapt: dE, exploded when SAH/saved SAH > 1 + dE (overrides the reading)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--adapt-overlap", a.update.adapt.max_overlap,
                    "adapt: exploded only when MaxOverlap exceeds this (default 0.5)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--cluster-heuristic", a.cluster_heuristic,
                    "clusters: acc (Acc(k) = reg - sizeBound * regBound; the default) | naive (the SAH baseline)")
        ->group(group);
    cmd->add_option("--cluster-generation", a.cluster_generation,
                    "clusters: merge (iterative merging on the dual graph; the default) | grow")
        ->group(group);
    cmd->add_option("--cluster-max-count", a.update.clusters.max_count, "clusters: MaxCount (default 50)")
        ->check(CLI::Range(1, 1000000))
        ->group(group);
    cmd->add_option("--cluster-max-size", a.update.clusters.max_size, "clusters: MaxSize (default 50)")
        ->check(CLI::Range(1e-3f, 1e6f))
        ->group(group);
    cmd->add_flag("--cluster-subtrees", a.update.clusters.cluster_subtrees,
                  "clusters: give each cluster its own small SAH tree, built once and refitted (not in the thesis; "
                  "leaves of --leaf-size triangles instead of whole clusters)")
        ->group(group);
    cmd->add_option("--cluster-leaf", a.update.clusters.leaf_triangles,
                    "clusters: the build over clusters stops at nodes of at most this many triangles (default 32)")
        ->check(CLI::Range(1, 64))
        ->group(group);
}

UpdateOptions to_update_options(const AccelArgs& a, const std::string& scene_default, const Device& device) {
    UpdateOptions update = a.update;
    const std::string& method = !a.update_method.empty() ? a.update_method : scene_default;
    update.method = method.empty() ? kDefaultUpdateMethod : parse_update_method(method);
    if (device.is_cuda() && !update_runs_on_device(update.method) && !a.update_method.empty())
        throw rf::Error("--update " + a.update_method + " runs on the CPU only; on " + to_string(device) +
                    " use refit, rebuild or two-level");
    if (device.is_cuda() && !update_runs_on_device(update.method)) {
        std::fprintf(stderr, "rayforge: note: the scene's update method %s runs on the CPU only; %s rebuilds\n",
                     method.c_str(), to_string(device).c_str());
        update.method = UpdateMethod::Rebuild;
    }
    if (!a.adapt_reading.empty()) {
        const AdaptOptions reading = parse_adapt_reading(a.adapt_reading);
        update.adapt.migrate_threshold = reading.migrate_threshold;
        update.adapt.explode_threshold = reading.explode_threshold;
    }
    if (a.adapt_dm > 0.0f) update.adapt.migrate_threshold = a.adapt_dm;
    if (a.adapt_de > 0.0f) update.adapt.explode_threshold = a.adapt_de;
    if (!a.cluster_heuristic.empty()) update.clusters.heuristic = parse_cluster_heuristic(a.cluster_heuristic);
    if (!a.cluster_generation.empty()) update.clusters.generation = parse_cluster_generation(a.cluster_generation);
    validate_update_options(update);
    return update;
}

BuildOptions to_build_options(const AccelArgs& a, int threads) {
    BuildOptions options = a.options;
    if (!a.accel.empty()) options.structure = parse_structure(a.accel);
    if (!a.builder.empty()) options.builder = parse_builder(a.builder);
    if (!a.layout.empty()) options.layout = parse_layout(a.layout);
    if (!a.kd_traversal.empty()) options.kdtree.traversal = parse_kd_traversal(a.kd_traversal);
    options.threads = threads;
    return options;
}

}  // namespace rf::cli
