// SAH kd-tree builder of Zlatuška 2009: binned SAH (min-max bins, Shevtsov et al.
// 2007) in the upper levels, below them the exact O(N log N) event sweep of
// Wald and Havran 2006 ("On building fast kd-trees for ray tracing, and on
// doing that in O(N log N)"), with optional perfect splits and the
// empty-space bonus.
#pragma once

#include <span>

#include "accel/kdtree/kdtree.h"
#include "rayforge/accel/accel.h"
#include "rayforge/scene/scene_geometry.h"

namespace rf {

// Nodes holding more triangle references than this are split with binned SAH;
// smaller ones with the exact event sweep.
inline constexpr size_t kKdExactSweepThreshold = 4096;

// The depth limit for n triangles: 8 + 1.3 log2(n) (Havran's rule of thumb),
// capped at kKdMaxDepth.
int kdtree_max_depth(size_t triangle_count);

// Builds over `triangles` with the SAH costs `sah`, binned.bin_count (the
// binned upper levels) and kdtree.perfect_splits and empty_bonus. Subtrees
// are built as parallel tasks; the result does not depend on the thread
// count. Zero-area triangles (which never produce hits) are left out.
KdTree build_kdtree(std::span<const Triangle> triangles, const SahCosts& sah, const BinnedSahOptions& binned,
                    const KdTreeOptions& kdtree);

}  // namespace rf
