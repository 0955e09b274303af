// rf::Accel over the SAH kd-tree (Wald and Havran 2006; kdtree_build.h),
// traced with one of the four traversals of trace/kdtree_traversal.h
// (accel/view_accel.h with KdTracer<traversal>).
#pragma once

#include <memory>

#include "accel/kdtree/kdtree.h"
#include "accel/view_accel.h"

namespace rf {

void describe_structure(const KdTree& tree, AccelStats& stats);

template <KdTraversal kMode>
using KdTreeAccel = ViewAccel<KdTree, KdTracer<kMode>>;

// Traces `tree`, built over `geometry` in `build_ms`, with `traversal`;
// `geometry` must outlive the result.
std::unique_ptr<Accel> make_kdtree_accel(const SceneGeometry& geometry, KdTree tree, KdTraversal traversal,
                                         int short_stack_size, double build_ms);

}  // namespace rf
