// The AFF directives for the camera, the lights and the animation's time
// range: v (viewpoint), l (point light), a (start, end, frames).
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"

namespace rf::io::aff {

// v from x y z at x y z up x y z angle deg hither h resolution w h, in any order, each at most once.
void AffParser::parse_view(long line) {
    ViewDef view;
    view.line = line;
    Token t;
    std::set<std::string> seen;
    while (in().peek(t)) {
        const std::string_view w = t.text;
        if (w != "from" && w != "at" && w != "up" && w != "angle" && w != "hither" && w != "resolution") break;
        in().next(t);
        if (!seen.insert(std::string(w)).second) throw error(t.line, "'" + std::string(w) + "' given twice in viewpoint");
        if (w == "from") view.from = in().read_vec3("viewpoint from");
        else if (w == "at") view.at = in().read_vec3("viewpoint at");
        else if (w == "up") view.up = in().read_vec3("viewpoint up");
        else if (w == "angle") {
            view.angle = in().read_float("viewpoint angle");
            if (!(view.angle > 0.0f && view.angle < 180.0f)) throw error(t.line, "viewpoint angle must be in (0, 180) degrees");
        } else if (w == "hither") {
            (void)in().read_float("viewpoint hither");
        } else {
            long rline = 0;
            const int64_t w0 = in().read_int("resolution", &rline);
            const int64_t h0 = in().read_int("resolution", &rline);
            if (w0 < 1 || h0 < 1 || w0 > 65536 || h0 > 65536)
                throw error(rline, "resolution " + std::to_string(w0) + " x " + std::to_string(h0) + " out of range");
            resolution_ = {int(w0), int(h0)};
        }
    }
    if (!(length(view.at - view.from) > 0.0f)) throw error(line, "viewpoint 'from' and 'at' are the same point");
    if (!(length(cross(view.at - view.from, view.up)) > 0.0f))
        throw error(line, "viewpoint 'up' is zero or parallel to the view direction");
    view_ = view;
}

// l x y z [r g b]
void AffParser::parse_light() {
    LightDef light;
    light.position = in().read_vec3("light position");
    light.color = Vec3f{1, 1, 1};
    if (in().next_is_number()) light.color = in().read_vec3("light color");
    budgeted_push_back(lights_, light, in().path() + ": AFF light array");
}

// a start end frames: the first `a` sets the default time and the animation's range.
void AffParser::parse_anim_params(long line) {
    const float start = in().read_float("animation start time");
    const float end = in().read_float("animation end time");
    long fline = 0;
    const int64_t frames = in().read_int("animation frame count", &fline);
    if (frames < 1) throw error(fline, "animation frame count must be at least 1");
    if (end < start) throw error(line, "animation ends before it starts");
    if (!anim_start_) {
        anim_start_ = start;
        anim_end_ = end;
        anim_frames_ = frames;
    }
}

}  // namespace rf::io::aff
