#include "accel_options.h"

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
