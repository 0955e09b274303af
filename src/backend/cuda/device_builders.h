// Acceleration-structure builders on a CUDA device, with the per-stage
// timing and peak device memory of each build (the public face is
// rf::build_bvh and rf::build_accel with a CUDA BuildOptions::device). The
// BVH builders are reached through build_bvh_on_device, as the CPU's through
// build_bvh_on_cpu; each one alone (device_bvh_builders.h) takes what its
// CPU counterpart takes. No CUDA header is needed to include this.
#pragma once

#include <cstddef>
#include <span>

#include "rayforge/accel/accel.h"
#include "rayforge/accel/build_report.h"
#include "rayforge/accel/bvh/bvh.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf::cuda {

// Milliseconds per stage of a device build. Device stages are timed with
// CUDA events around their kernels; transfers and host work are separate.
struct DeviceBuildStages {
    double upload_ms = 0.0;       // triangles to the device
    double bounds_ms = 0.0;       // per-triangle boxes and the bounds reduction (centroids; grids: triangles)
    double morton_ms = 0.0;       // Morton codes
    double sort_ms = 0.0;         // radix sort of (code, triangle) pairs
    double inner_nodes_ms = 0.0;  // Karras's inner-node construction
    double boxes_ms = 0.0;        // bottom-up boxes with atomic counters
    double download_ms = 0.0;     // the result back to the host (the canonical BVH, or the raw tree)
    double device_emit_ms = 0.0;  // LBVH, HLBVH2, PLOC: leaf collapse and canonical layout on the device;
                                  // GridBvh: subtree sizes, boxes, positions and the canonical layout
    double emit_ms = 0.0;         // host: leaf collapse and canonical emission (when the device did not)
    bool emitted_on_device = false; // false when the host emitted: LBVH, HLBVH2, PLOC trees deeper than
                                    // kBvhMaxDepth; GridBvh leaves of more than 64 references (crowded cells)
    size_t peak_device_bytes = 0; // sum of the live device buffers at the peak
    // HLBVH2 only (zero for LBVH):
    double clusters_ms = 0.0;     // compaction of runs of equal 15-bit prefixes, the level-0 tasks
    double bottom_ms = 0.0;       // bottom levels by work queues, one launch per level (boxes_ms: their boxes)
    double top_ms = 0.0;          // top level over the cluster boxes by task queues (its boxes: boxes_ms)
    uint32_t cluster_count = 0;   // clusters (bottom trees)
    uint32_t bottom_levels = 0;   // HLBVH2: launches of the bottom trees (1: every split position at once)
    uint32_t top_levels = 0;      // HLBVH2: task-queue levels of the device top level (all in one launch)
    // PLOC only:
    double ploc_ms = 0.0;         // all iterations: nearest neighbours, merges, compaction
    uint32_t ploc_iterations = 0; // iterations until one cluster is left
    // H-PLOC only:
    double hploc_ms = 0.0;        // the single launch: LBVH climb and PLOC per range, with its slot clears
    // GridBvh / GridBvhSplit only (Garanzha 2014 ch. 4; sort_ms: the cell-key sort):
    double partial_triangles_ms = 0.0; // references and their splitting (§4.4)
    double grid0_ms = 0.0;        // TopGrid0 and the 8^3 bottom grids by compaction (§4.2)
    double coarse_levels_ms = 0.0;// count-only levels of detail
    double hierarchy_ms = 0.0;    // EmitHierarchy by task queues (§4.3)
    double leaf_finish_ms = 0.0;  // leaf gathering and splitting of leaves over 4 references
    size_t references = 0;        // GridBvh: (partial) triangle references; uniform grid: cell references
    size_t occupied_top_cells = 0;// non-empty TopGrid0 cells
    // Uniform grid only (Kalojanov and Slusallek 2009; sort_ms: the pair sort):
    double cell_pairs_ms = 0.0;   // counting and writing (cell, triangle) pairs
    double cell_ranges_ms = 0.0;  // cell start offsets from the sorted pairs
    double proximity_ms = 0.0;    // proximity-cloud distance transform

    // Any builder:
    double treelet_ms = 0.0;      // device: treelet restructuring (options.treelets), its emission included
    double optimize_ms = 0.0;     // host: reinsertion optimizer (options.reinsertion) after a device build
    double layout_ms = 0.0;       // device layout conversion (node pairs, CWBVH) when a tracer asked for one
    double first_ray_ms = 0.0;    // a tracer's device build: host wall time from the start of the build to the
                                  // traced layout in the tracer's buffers, synchronized, less the triangles'
                                  // uploads (the device-resident chain: no tree download in it; issue 33)
    double build_span_ms = 0.0;   // a tracer's device build: one CUDA event pair around the whole build (the
                                  // per-stage timers' host syncs and the builder's triangle upload inside it)
    bool on_device = false;       // false: this structure was built on the host (no device builder, or asked so)

    // The build on the device alone: every stage above that runs there (not
    // the transfers, the host's emission and optimizer, or a layout conversion).
    [[nodiscard]] double device_total_ms() const {
        return bounds_ms + morton_ms + sort_ms + inner_nodes_ms + clusters_ms + bottom_ms + top_ms + boxes_ms + ploc_ms + hploc_ms +
               device_emit_ms + partial_triangles_ms + grid0_ms + coarse_levels_ms + hierarchy_ms + leaf_finish_ms + cell_pairs_ms +
               cell_ranges_ms + proximity_ms + treelet_ms;
    }
};

// The stages that ran, as the public report.
BuildReport describe_device_build(const DeviceBuildStages& stages, const Device& device);

struct DeviceBvh;

// Whether options.builder has a device version: lbvh30, lbvh63, hlbvh2,
// ploc, hploc, gridbvh, gridbvh-split.
bool has_device_builder(Builder builder);

// The BVH of options.builder built on device `device` with its options
// group (then treelet restructuring on the device when
// options.treelets.enabled is set, and the host's reinsertion optimizer when
// options.reinsertion.enabled is), the host's share on at most
// options.threads threads: the same BVH as rf::build_bvh. Throws rf::Error
// for a builder without a device version. `resident` (device_bvh.h): the
// tree kept on the device when the builder emitted it there and no
// optimizer runs (the returned Bvh then empty), see device_bvh_builders.h.
Bvh build_bvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options,
                        DeviceBuildStages* stages = nullptr, int device = 0, DeviceBvh* resident = nullptr);

}  // namespace rf::cuda

namespace rf {
struct UniformGrid;
struct AilaLaineBvh;
struct CwbvhBvh;
}  // namespace rf

namespace rf::cuda {

// Uniform grid by sorting (cell, triangle) pairs (Kalojanov and Slusallek
// 2009) on device `device`, with the proximity-cloud distance transform when
// asked: the same grid as rf::build_uniform_grid (same layout, same cell
// lists in ascending triangle order, same distances).
UniformGrid build_uniform_grid_on_device(std::span<const Triangle> triangles, int resolution,
                                         bool proximity_clouds, DeviceBuildStages* stages = nullptr,
                                         int device = 0);

// Conversions of a canonical BVH to the GPU traversal layouts on device
// `device`, timed separately (`device_ms`: the kernels, CUDA events): the same
// result as rf::convert_to_aila_laine and rf::build_cwbvh.
AilaLaineBvh convert_to_aila_laine_on_device(const Bvh& bvh, std::span<const Triangle> triangles,
                                             double* device_ms = nullptr, int device = 0);
CwbvhBvh build_cwbvh_on_device(const Bvh& bvh, std::span<const Triangle> triangles, double* device_ms = nullptr,
                               int device = 0);

// The device-resident chain that DeviceTracer runs for a device build
// (device_bvh.h, layout_convert.h): options.builder on device `device`, the
// tree kept there, converted there; the layout downloaded only at the end,
// to compare it with the host chain's (build_bvh_on_device, then the
// functions above). Throws rf::Error for a builder without a device version.
AilaLaineBvh resident_aila_laine_on_device(std::span<const Triangle> triangles, const BuildOptions& options,
                                           int device = 0);
CwbvhBvh resident_cwbvh_on_device(std::span<const Triangle> triangles, const BuildOptions& options, int device = 0);

}  // namespace rf::cuda
