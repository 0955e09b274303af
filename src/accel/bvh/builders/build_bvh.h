// The CPU's one entry point for every BVH builder: runs the builder named in
// options.builder with its options group, then the optimizers when asked
// (treelet restructuring for options.treelets.enabled, then reinsertion for
// options.reinsertion.enabled), all on at most options.threads
// threads. The public rf::build_bvh (rayforge/accel/accel.h) calls it for
// the CPU.
#pragma once

#include <span>

#include "core/progress_meter.h"
#include "rayforge/accel/accel.h"
#include "rayforge/accel/bvh/bvh.h"

namespace rf {

// Options are assumed validated (build_accel). The result satisfies the
// canonical BVH invariants (rayforge/accel/bvh/bvh.h): depth-first order,
// siblings adjacent, depth <= kBvhMaxDepth, leaves of at most max_leaf_size
// references. Builders with spatial splits (SBVH, GridBvhSplit) may reference
// a triangle from several leaves; all others reference each exactly once.
// `progress`, when given, counts the references placed in leaves by the
// builders that report it (binned, sweep, SBVH); others report nothing.
Bvh build_bvh_on_cpu(std::span<const Triangle> triangles, const BuildOptions& options,
                     ProgressMeter* progress = nullptr);

}  // namespace rf
