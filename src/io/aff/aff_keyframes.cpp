// An AFF `k` block's matrix and visibility at one time, through the scene
// model's track evaluation (one implementation of BART's splines and squad).
#include "io/aff/aff_keyframes.h"

#include "scene/animation_eval.h"

namespace rf::io::aff {

AnimatedNode Animation::node(const std::string& name) const {
    AnimatedNode n;
    n.name = name;
    n.translation_track = transl;
    n.rotation_track = rot;
    n.scale_track = scale;
    n.visibility = visibility;
    return n;
}

Affine3f Animation::matrix(double t) const { return node_local_transform(node(""), float(t)); }

bool Animation::visible(double t) const { return node_visible(node(""), float(t)); }

}  // namespace rf::io::aff
