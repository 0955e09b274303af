// AFF transform blocks and their keyframes: xs (static T*R*S), x (animated,
// named) and k (the keyframes of a name: transl, rot, scale, visibility).
// Blocks are nodes of a tree; '}' (in aff_parser.cpp) closes the innermost.
#include <limits>
#include <set>
#include <string>

#include "io/aff/aff_parser.h"
#include "rayforge/core/memory_budget.h"
#include "scene/animation_eval.h"

namespace rf::io::aff {

namespace {

// `count` keys, each: time, 3 values (rot: axis and angle in degrees), tension,
// continuity, bias; into a Kochanek-Bartels track (rot: quaternions, width 4).
void read_keys(TokenReader& in, Track& track, size_t count, bool rotation, const std::string& what) {
    track = Track{};
    track.interpolation = Interpolation::KochanekBartels;
    track.width = rotation ? 4 : 3;
    budgeted_reserve(track.times, count, what);
    budgeted_reserve(track.values, count * size_t(track.width), what);
    budgeted_reserve(track.tcb, count, what);
    for (size_t i = 0; i < count; ++i) {
        // Times that go back (Robot1.aff has some) are kept: the segment search
        // (kb_segment in src/scene/animation.cpp), like BART's, takes the first segment that ends after t.
        track.times.push_back(in.read_float("keyframe time"));
        double v[4];
        for (int c = 0; c < (rotation ? 4 : 3); ++c) v[c] = in.read_float("keyframe value");
        if (rotation) {
            const Vec4f q = axis_angle_quaternion(v[0], v[1], v[2], v[3] * kPi / 180.0);
            track.values.insert(track.values.end(), {q.x, q.y, q.z, q.w});
        } else {
            track.values.insert(track.values.end(), {float(v[0]), float(v[1]), float(v[2])});
        }
        const float tension = in.read_float("keyframe tension");
        const float continuity = in.read_float("keyframe continuity");
        const float bias = in.read_float("keyframe bias");
        track.tcb.push_back(Vec3f{tension, continuity, bias});
    }
}

// visibility N (time flag)*N: a step track that is visible before the first key;
// a key at the time of the one before it replaces it (BART applies both, in order).
void read_visibility(TokenReader& in, Track& track, size_t count, const std::string& what) {
    track = Track{};
    track.interpolation = Interpolation::Step;
    track.width = 1;
    budgeted_reserve(track.times, count + 1, what);
    budgeted_reserve(track.values, count + 1, what);
    track.times.push_back(std::numeric_limits<float>::lowest());
    track.values.push_back(1.0f);
    for (size_t i = 0; i < count; ++i) {
        Token next;
        const long tline = in.peek(next) ? next.line : 0;
        const float time = in.read_float("visibility time");
        long vline = 0;
        const int64_t flag = in.read_int("visibility flag", &vline);
        if (flag != 0 && flag != 1) throw in.error(vline, "visibility flag must be 0 or 1");
        if (time < track.times.back()) throw in.error(tline, "visibility times must not decrease");
        if (time == track.times.back()) track.values.back() = float(flag);
        else track.times.push_back(time), track.values.push_back(float(flag));
    }
}

}  // namespace

void AffParser::push_node(Node node) {
    node.parent = current_node();
    node.file = in().path();
    budgeted_push_back(nodes_, std::move(node), root_ + ": AFF transform array");
    budgeted_push_back(node_stack_, int(nodes_.size() - 1), root_ + ": AFF transform stack");
}

// xs sx sy sz  rx ry rz angle_deg  tx ty tz { ... }: T*R*S
void AffParser::parse_static_transform(long line) {
    const Vec3f s = in().read_vec3("static transform scale");
    const Vec3f axis = in().read_vec3("static transform rotation axis");
    const float degrees = in().read_float("static transform rotation angle");
    const Vec3f tr = in().read_vec3("static transform translation");
    in().expect_open_brace("xs");
    if (s.x == 0.0f || s.y == 0.0f || s.z == 0.0f) throw error(line, "static transform has a zero scale");
    Affine3f r = Affine3f::identity();
    if (length(axis) > 0.0f) r = Affine3f::rotation(axis, degrees * float(kPi / 180.0));
    else if (degrees != 0.0f) throw error(line, "static transform rotates about a zero axis");
    Node node;
    node.local = Affine3f::translation(tr) * r * Affine3f::scale(s);
    node.line = line;
    push_node(std::move(node));
}

// x name { ... }: evaluated from `k name` at the end (the identity when there is none).
void AffParser::parse_animated_transform(long line) {
    Node node;
    node.animated = true;
    node.name = in().read_word("transform name");
    node.line = line;
    in().expect_open_brace("x");
    push_node(std::move(node));
}

// k name { transl N ... rot N ... scale N ... visibility N ... }
void AffParser::parse_keyframes(long line) {
    const std::string name = in().read_word("animation name");
    in().expect_open_brace("k");
    Animation anim;
    anim.file = in().path();
    anim.line = line;
    std::set<std::string> seen;
    for (;;) {
        Token t = in().expect_token("keyframe type or '}'");
        if (t.text == "}") break;
        const std::string type(t.text);
        if (type != "transl" && type != "rot" && type != "scale" && type != "visibility")
            throw error(t.line, "unknown keyframe type '" + type.substr(0, 32) + "' (transl, rot, scale or visibility)");
        if (!seen.insert(type).second) throw error(t.line, "'" + type + "' given twice in animation '" + name + "'");
        const size_t numbers = type == "rot" ? 8 : type == "visibility" ? 2 : 7;
        const size_t count = in().read_count("keyframe count", numbers);
        if (type == "visibility") {
            read_visibility(in(), anim.visibility, count, root_ + ": AFF keyframes");
            continue;
        }
        if (count < 4)
            throw error(t.line, "'" + type + "' of animation '" + name +
                                    "' needs at least 4 keyframes (the first and last only shape the spline)");
        Track& keys = type == "transl" ? anim.transl : type == "rot" ? anim.rot : anim.scale;
        read_keys(in(), keys, count, type == "rot", root_ + ": AFF keyframes");
    }
    animations_[name] = std::move(anim);  // a later definition replaces an earlier one
}

}  // namespace rf::io::aff
