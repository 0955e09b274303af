#include "accel_options.h"

#include "option_binding.h"

namespace rf::cli {

void add_accel_options(CLI::App* cmd, BuildOptions& build) {
    const BuildOptions defaults;
    const std::string group = "Acceleration structure";
    add_named_option(cmd, "--accel", build.structure, parse_structure,
                     {"bvh", "grid", "grid-proximity", "kdtree", "brute"},
                     "Structure: bvh | grid | grid-proximity | kdtree | brute (default " +
                         to_string(defaults.structure) + "; with --device cuda the --gpu-kernel's when not given)")
        ->group(group);
    add_named_option(cmd, "--builder", build.builder, parse_builder,
                     {"binned", "sweep", "sbvh", "lbvh", "lbvh30", "lbvh63", "hlbvh2", "gridbvh", "gridbvh-split", "ploc",
                      "hploc"},
                     "BVH builder: binned | sweep | sbvh | lbvh30 | lbvh63 | hlbvh2 | gridbvh | gridbvh-split | ploc | "
                     "hploc "
                     "(default " + to_string(defaults.builder) + ")")
        ->group(group);
    add_named_option(cmd, "--layout", build.layout, parse_layout, {"bvh2", "bvh4", "bvh8"},
                     "BVH layout traced on the CPU: bvh2 | bvh4 | bvh8 (default " + to_string(defaults.layout) + ")")
        ->group(group);
    cmd->add_flag("--optimize", build.reinsertion.enabled, "Optimise the BVH by reinsertion after building")
        ->group(group);
    cmd->add_option("--optimize-iterations", build.reinsertion.iterations,
                    "Reinsertion rounds (default 0 = until it stops improving)")
        ->check(CLI::Range(0, 1000))
        ->group(group);
    cmd->add_flag("--treelets", build.treelets.enabled,
                  "Optimise the BVH by treelet restructuring after building (Karras and Aila 2013)")
        ->group(group);
    cmd->add_option("--treelet-leaves", build.treelets.treelet_leaves, "Treelet restructuring: leaves per treelet (default 7)")
        ->check(CLI::Range(3, 7))
        ->group(group);
    cmd->add_option("--treelet-rounds", build.treelets.rounds, "Treelet restructuring: rounds (default 3)")
        ->check(CLI::Range(1, 16))
        ->group(group);
    cmd->add_option("--bins", build.binned.bin_count, "SAH bins per axis of binned builders (default 16)")
        ->check(CLI::Range(2, 256))
        ->group(group);
    cmd->add_option("--leaf-size", build.max_leaf_size, "Most triangles per BVH leaf (default 4)")
        ->check(CLI::Range(1, 64))
        ->group(group);
    cmd->add_option("--sbvh-alpha", build.sbvh.alpha,
                    "SBVH: try spatial splits above this overlap / root area (default 1e-5)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--ploc-radius", build.ploc.radius, "PLOC and H-PLOC nearest-neighbour search radius (default 16; H-PLOC: at most 31)")
        ->check(CLI::Range(1, 256))
        ->group(group);
    cmd->add_option("--split-budget", build.grid_bvh.split_budget,
                    "GridBvhSplit: partial triangles as a fraction of the triangle count (default 0.3)")
        ->check(CLI::Range(0.0f, 4.0f))
        ->group(group);
    cmd->add_option("--grid-res", build.grid.resolution,
                    "Grids: cells on the longest axis (default 0 = 4 n^(1/4) on the shortest axis, cubic cells)")
        ->check(CLI::Range(0, 2048))
        ->group(group);
    add_named_option(cmd, "--kd-traversal", build.kdtree.traversal, parse_kd_traversal,
                     {"stack", "short-stack", "restart", "pushdown"},
                     "kd-tree traversal: stack | short-stack | restart | pushdown (default stack)")
        ->group(group);
}

void add_update_options(CLI::App* cmd, UpdateOptions& update) {
    const std::string group = "Animation: acceleration-structure updates";
    // Unknown names are runtime errors here (exit 1), as a scene file's would be.
    cmd->add_option_function<std::string>(
           "--update", [&update](const std::string& name) { update.method = parse_update_method(name); },
           "How the structure follows an animation: refit | adapt (Garanzha 2014 ch. 2: refit, local "
           "rebuilds, migrations) | rebuild | clusters (ch. 3: builds over precomputed clusters) | "
           "two-level (a BVH per mesh, a top level over instances); on --device cuda refit, rebuild "
           "and two-level (default: the scene's, else " +
               to_string(kDefaultUpdateMethod) + ")")
        ->group(group);
    // Defined before --adapt-dm and --adapt-de, whose values then override it (CLI11 runs
    // option callbacks in the order the options were added).
    cmd->add_option_function<std::string>(
           "--adapt-reading",
           [&update](const std::string& name) {
               const AdaptOptions reading = parse_adapt_reading(name);
               update.adapt.migrate_threshold = reading.migrate_threshold;
               update.adapt.explode_threshold = reading.explode_threshold;
           },
           "adapt: the text's two readings of its swapped thresholds: stated (dM 0.05, dE 0.01; the "
           "default) | closing (dM 0.01, dE 0.05)")
        ->group(group);
    cmd->add_option("--adapt-dm", update.adapt.migrate_threshold,
                    "adapt: dM, migrating when SAH/saved SAH < 1 - dM (overrides the reading)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--adapt-de", update.adapt.explode_threshold,
                    "adapt: dE, exploded when SAH/saved SAH > 1 + dE (overrides the reading)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    cmd->add_option("--adapt-overlap", update.adapt.max_overlap,
                    "adapt: exploded only when MaxOverlap exceeds this (default 0.5)")
        ->check(CLI::Range(0.0f, 1.0f))
        ->group(group);
    add_named_option(cmd, "--cluster-heuristic", update.clusters.heuristic, parse_cluster_heuristic, {"acc", "naive"},
                     "clusters: acc (Acc(k) = reg - sizeBound * regBound; the default) | naive (the SAH baseline)")
        ->group(group);
    add_named_option(cmd, "--cluster-generation", update.clusters.generation, parse_cluster_generation,
                     {"merge", "grow"}, "clusters: merge (iterative merging on the dual graph; the default) | grow")
        ->group(group);
    cmd->add_option("--cluster-max-count", update.clusters.max_count, "clusters: MaxCount (default 50)")
        ->check(CLI::Range(1, 1000000))
        ->group(group);
    cmd->add_option("--cluster-max-size", update.clusters.max_size, "clusters: MaxSize (default 50)")
        ->check(CLI::Range(1e-3f, 1e6f))
        ->group(group);
    cmd->add_flag("--cluster-subtrees", update.clusters.cluster_subtrees,
                  "clusters: give each cluster its own small SAH tree, built once and refitted (not in the thesis; "
                  "leaves of --leaf-size triangles instead of whole clusters)")
        ->group(group);
    cmd->add_option("--cluster-leaf", update.clusters.leaf_triangles,
                    "clusters: the build over clusters stops at nodes of at most this many triangles (default 32)")
        ->check(CLI::Range(1, 64))
        ->group(group);
}

}  // namespace rf::cli
