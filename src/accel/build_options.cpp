// BuildOptions as text and as checked values: the names of structures,
// builders, layouts and kd-tree traversals, validate_build_options, and the
// structure each GPU kernel traverses. Apart from the dispatch
// (accel.cpp), so that whatever parses options (the CLI, the viewer and its
// fuzz target) needs none of the builders.
#include <cmath>
#include <string>
#include <utility>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/dynamic_accel.h"
#include "accel/device_structure.h"
#include "rayforge/core/error.h"

namespace rf {

void validate_build_options(const BuildOptions& options) {
    if (options.binned.bin_count < 2 || options.binned.bin_count > 256) {
        throw Error("build options: binned.bin_count must be in [2, 256], got " +
                    std::to_string(options.binned.bin_count));
    }
    if (options.max_leaf_size < 1 || options.max_leaf_size > 64) {
        throw Error("build options: max_leaf_size must be in [1, 64], got " +
                    std::to_string(options.max_leaf_size));
    }
    if (!(options.sah.traversal > 0.0f) || !std::isfinite(options.sah.traversal)) {
        throw Error("build options: sah.traversal must be a positive number, got " +
                    std::to_string(options.sah.traversal));
    }
    if (!(options.sah.intersection > 0.0f) || !std::isfinite(options.sah.intersection)) {
        throw Error("build options: sah.intersection must be a positive number, got " +
                    std::to_string(options.sah.intersection));
    }
    if (options.reinsertion.iterations < 0 || options.reinsertion.iterations > 1000) {
        throw Error("build options: reinsertion.iterations must be in [0, 1000], got " +
                    std::to_string(options.reinsertion.iterations));
    }
    if (options.treelets.treelet_leaves < 3 || options.treelets.treelet_leaves > 7) {
        throw Error("build options: treelets.treelet_leaves must be in [3, 7], got " +
                    std::to_string(options.treelets.treelet_leaves));
    }
    if (options.treelets.rounds < 1 || options.treelets.rounds > 16) {
        throw Error("build options: treelets.rounds must be in [1, 16], got " +
                    std::to_string(options.treelets.rounds));
    }
    if (!(options.sbvh.alpha >= 0.0f && options.sbvh.alpha <= 1.0f)) {
        throw Error("build options: sbvh.alpha must be in [0, 1], got " + std::to_string(options.sbvh.alpha));
    }
    if (options.ploc.radius < 1 || options.ploc.radius > 256) {
        throw Error("build options: ploc.radius must be in [1, 256], got " + std::to_string(options.ploc.radius));
    }
    if (!(options.grid_bvh.split_budget >= 0.0f && options.grid_bvh.split_budget <= 4.0f)) {
        throw Error("build options: grid_bvh.split_budget must be in [0, 4], got " +
                    std::to_string(options.grid_bvh.split_budget));
    }
    if (options.grid.resolution < 0 || options.grid.resolution > 2048) {
        throw Error("build options: grid.resolution must be in [0, 2048] (0 = automatic), got " +
                    std::to_string(options.grid.resolution));
    }
    if (!(options.kdtree.empty_bonus >= 0.0f && options.kdtree.empty_bonus < 1.0f)) {
        throw Error("build options: kdtree.empty_bonus must be in [0, 1), got " +
                    std::to_string(options.kdtree.empty_bonus));
    }
    if (options.kdtree.short_stack_size < 1 || options.kdtree.short_stack_size > 64) {
        throw Error("build options: kdtree.short_stack_size must be in [1, 64], got " +
                    std::to_string(options.kdtree.short_stack_size));
    }
    if (options.threads < 0) {
        throw Error("build options: threads must be >= 0 (0 = all cores), got " + std::to_string(options.threads));
    }
    if (options.device.is_cuda() && structure_of(options.gpu_kernel) != options.structure) {
        throw Error("build options: the GPU kernel " + to_string(options.gpu_kernel) + " traverses a " +
                    to_string(structure_of(options.gpu_kernel)) + ", not a " + to_string(options.structure));
    }
}

BuildOptions with_device_structure(BuildOptions options) {
    if (!options.device.is_cuda()) return options;
    const Structure traversed = structure_of(options.gpu_kernel);
    if (traversed == options.structure) return options;
    if (options.structure == Structure::Bvh) {  // the default structure: the kernel decides
        options.structure = traversed;
        return options;
    }
    if (options.gpu_kernel == kDefaultGpuKernel) {  // the default kernel: the structure's own
        switch (options.structure) {
            case Structure::Grid: options.gpu_kernel = GpuKernel::Grid; return options;
            case Structure::ProximityGrid: options.gpu_kernel = GpuKernel::ProximityGrid; return options;
            case Structure::KdTree: options.gpu_kernel = GpuKernel::KdShortStack; return options;
            case Structure::BruteForce:
                throw Error("build options: no GPU kernel traverses brute force (" + to_string(options.device) +
                            ": choose bvh, kdtree, grid or grid-proximity)");
            case Structure::Bvh: break;
        }
    }
    throw Error("build options: the GPU kernel " + to_string(options.gpu_kernel) + " traverses a " +
                to_string(traversed) + ", not a " + to_string(options.structure));
}

Structure structure_of(GpuKernel kernel) {
    switch (kernel) {
        case GpuKernel::KdShortStack:
        case GpuKernel::KdRestart: return Structure::KdTree;
        case GpuKernel::Grid: return Structure::Grid;
        case GpuKernel::ProximityGrid: return Structure::ProximityGrid;
        case GpuKernel::Bvh2:
        case GpuKernel::AilaLaine:
        case GpuKernel::AilaLaineFma:
        case GpuKernel::Cwbvh:
        case GpuKernel::CwbvhFma: break;
    }
    return Structure::Bvh;
}

namespace {

template <typename Enum, size_t N>
Enum parse_name(const std::string& name, const std::pair<const char*, Enum> (&names)[N], const char* what) {
    for (const auto& [text, value] : names)
        if (name == text) return value;
    std::string known;
    for (const auto& [text, value] : names) known += (known.empty() ? "" : ", ") + std::string(text);
    throw Error("unknown " + std::string(what) + " '" + name + "' (expected one of: " + known + ")");
}

template <typename Enum, size_t N>
std::string name_of(Enum value, const std::pair<const char*, Enum> (&names)[N]) {
    for (const auto& [text, v] : names)
        if (v == value) return text;
    return "?";
}

constexpr std::pair<const char*, Structure> kStructureNames[] = {
    {"bvh", Structure::Bvh},      {"grid", Structure::Grid},         {"grid-proximity", Structure::ProximityGrid},
    {"kdtree", Structure::KdTree}, {"brute", Structure::BruteForce},
};
// "lbvh" (an alias of lbvh30) comes after lbvh30 so that to_string gives "lbvh30".
constexpr std::pair<const char*, Builder> kBuilderNames[] = {
    {"binned", Builder::BinnedSah}, {"sweep", Builder::SweepSah},   {"sbvh", Builder::Sbvh},
    {"lbvh30", Builder::Lbvh30},    {"lbvh63", Builder::Lbvh63},    {"lbvh", Builder::Lbvh30},
    {"hlbvh2", Builder::Hlbvh2},    {"gridbvh", Builder::GridBvh},  {"gridbvh-split", Builder::GridBvhSplit},
    {"ploc", Builder::Ploc},        {"hploc", Builder::Hploc},
};
constexpr std::pair<const char*, Layout> kLayoutNames[] = {
    {"bvh2", Layout::Bvh2}, {"bvh4", Layout::Bvh4}, {"bvh8", Layout::Bvh8}};
constexpr std::pair<const char*, KdTraversal> kKdTraversalNames[] = {
    {"stack", KdTraversal::Stack}, {"short-stack", KdTraversal::ShortStack},
    {"restart", KdTraversal::Restart}, {"pushdown", KdTraversal::Pushdown}};
constexpr std::pair<const char*, UpdateMethod> kUpdateMethodNames[] = {
    {"refit", UpdateMethod::Refit},       {"adapt", UpdateMethod::Adapt},
    {"rebuild", UpdateMethod::Rebuild},   {"clusters", UpdateMethod::Clusters},
    {"two-level", UpdateMethod::TwoLevel}};
constexpr std::pair<const char*, ClusterHeuristic> kClusterHeuristicNames[] = {
    {"acc", ClusterHeuristic::Acc}, {"naive", ClusterHeuristic::Naive}};
constexpr std::pair<const char*, ClusterGeneration> kClusterGenerationNames[] = {
    {"merge", ClusterGeneration::Merge}, {"grow", ClusterGeneration::Grow}};

}  // namespace

Structure parse_structure(const std::string& name) { return parse_name(name, kStructureNames, "acceleration structure"); }
Builder parse_builder(const std::string& name) { return parse_name(name, kBuilderNames, "BVH builder"); }
Layout parse_layout(const std::string& name) { return parse_name(name, kLayoutNames, "BVH layout"); }
KdTraversal parse_kd_traversal(const std::string& name) {
    return parse_name(name, kKdTraversalNames, "kd-tree traversal");
}
std::string to_string(Structure structure) { return name_of(structure, kStructureNames); }
std::string to_string(Builder builder) { return name_of(builder, kBuilderNames); }
std::string to_string(Layout layout) { return name_of(layout, kLayoutNames); }
std::string to_string(KdTraversal traversal) { return name_of(traversal, kKdTraversalNames); }

}  // namespace rf

namespace rf {

bool update_runs_on_device(UpdateMethod method) {
    return method == UpdateMethod::Refit || method == UpdateMethod::Rebuild || method == UpdateMethod::TwoLevel;
}

UpdateMethod parse_update_method(const std::string& name) {
    return parse_name(name, kUpdateMethodNames, "update method");
}
ClusterHeuristic parse_cluster_heuristic(const std::string& name) {
    return parse_name(name, kClusterHeuristicNames, "cluster heuristic");
}
ClusterGeneration parse_cluster_generation(const std::string& name) {
    return parse_name(name, kClusterGenerationNames, "cluster generation");
}
AdaptOptions parse_adapt_reading(const std::string& name) {
    if (name == "stated") return AdaptOptions::stated();
    if (name == "closing") return AdaptOptions::closing();
    throw Error("unknown adapt reading '" + name + "' (expected one of: stated, closing)");
}
std::string to_string(UpdateMethod method) { return name_of(method, kUpdateMethodNames); }
std::string to_string(ClusterHeuristic heuristic) { return name_of(heuristic, kClusterHeuristicNames); }
std::string to_string(ClusterGeneration generation) { return name_of(generation, kClusterGenerationNames); }

void validate_update_options(const UpdateOptions& update) {
    const AdaptOptions& a = update.adapt;
    const auto fraction = [](float v) { return std::isfinite(v) && v > 0.0f && v < 1.0f; };
    if (!fraction(a.migrate_threshold))
        throw Error("adapt: dM (migrate threshold) must be in (0, 1), got " + std::to_string(a.migrate_threshold));
    if (!fraction(a.explode_threshold))
        throw Error("adapt: dE (explode threshold) must be in (0, 1), got " + std::to_string(a.explode_threshold));
    if (!(a.max_overlap >= 0.0f && a.max_overlap <= 1.0f))
        throw Error("adapt: max overlap must be in [0, 1], got " + std::to_string(a.max_overlap));
    const ClusterOptions& c = update.clusters;
    if (c.max_count < 1 || c.max_count > 1000000)
        throw Error("clusters: max count must be in [1, 1000000], got " + std::to_string(c.max_count));
    if (!(c.max_size > 0.0f && c.max_size <= 1e6f))
        throw Error("clusters: max size must be in (0, 1e6], got " + std::to_string(c.max_size));
    if (c.leaf_triangles < 1 || c.leaf_triangles > 64)
        throw Error("clusters: leaf triangles must be in [1, 64], got " + std::to_string(c.leaf_triangles));
}

}  // namespace rf
