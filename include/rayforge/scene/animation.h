// Time in the scene model: keyframed transforms on a node hierarchy (glTF
// nodes, BART's `k` blocks, JSON keys), vertex keyframes, linear-blend
// skinning and morph targets, and camera paths. A loader fills
// Scene::animation; Scene::set_time(t) evaluates it in place (instance
// transforms, the positions and normals of deformed meshes, the camera) and
// says what moved, so an accel can be updated rather than rebuilt.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "rayforge/math/affine.h"
#include "rayforge/math/vec.h"
#include "rayforge/scene/camera.h"

namespace rf {

// How a track interpolates between its keys.
//   Step: the previous key's value (glTF STEP, BART visibility).
//   Linear: lerp; rotations slerp (glTF LINEAR, JSON keys).
//   CubicSpline: glTF CUBICSPLINE (Hermite, in/out tangents per key).
//   KochanekBartels: BART's splines: positions and scales on a Kochanek-Bartels
//     curve with per-key tension/continuity/bias, rotations by squad over the
//     same weights (Lext, Assarsson and Möller 2001; the AFF loader's math).
enum class Interpolation : uint8_t { Step, Linear, CubicSpline, KochanekBartels };

// Keys of one animated property. `values` holds `width` floats per key
// (3 for translation/scale, 4 for a quaternion x,y,z,w, the target count for
// morph weights); CubicSpline holds three groups per key (in-tangent, value,
// out-tangent, as glTF stores them). KochanekBartels keys have one tcb
// (tension, continuity, bias) each. Times are seconds, strictly increasing.
// Before the first key the track holds its first value, after the last its last.
struct Track {
    Interpolation interpolation = Interpolation::Linear;
    int width = 3;
    std::vector<float> times;
    std::vector<float> values;
    std::vector<Vec3f> tcb;  // KochanekBartels only: one per key
    [[nodiscard]] bool empty() const { return times.empty(); }
    [[nodiscard]] size_t key_count() const { return times.size(); }
};

// A node of the transform hierarchy. Its local transform is T * R * S from
// the rest values, each replaced by its track when the track has keys; a
// node with a rest matrix (glTF `matrix`) has no tracks. World = parent's
// world * local. `visibility`, when not empty, is a step track of 0/1
// (BART's visibility keys); an invisible node hides the instances under it.
struct AnimatedNode {
    std::string name;
    int32_t parent = -1;  // index into Animation::nodes, always smaller than this node's
    Vec3f translation{0.0f, 0.0f, 0.0f};
    Vec4f rotation{0.0f, 0.0f, 0.0f, 1.0f};  // unit quaternion x, y, z, w
    Vec3f scale{1.0f, 1.0f, 1.0f};
    std::optional<Affine3f> matrix;         // replaces T * R * S when set
    Track translation_track, rotation_track, scale_track, visibility;
};

// Instance i's transform at time t = world(node) * local. A hidden instance
// keeps its triangles (so the triangle order and count never change) but
// collapses them to one point: zero-area triangles never hit.
struct InstanceAnimation {
    uint32_t instance = 0;
    uint32_t node = 0;
    Affine3f local = Affine3f::identity();
};

// Per-vertex animation of a mesh in object space: `positions[k]` (and
// `normals[k]` when not empty) are the mesh's vertices at `times[k]`;
// interpolation is Step or Linear.
struct VertexKeyframes {
    uint32_t mesh = 0;
    Interpolation interpolation = Interpolation::Linear;
    std::vector<float> times;
    std::vector<std::vector<Vec3f>> positions;
    std::vector<std::vector<Vec3f>> normals;
};

// Morph targets of a mesh (glTF): position (and normal) offsets per target,
// weighted by `weights` (width = target count) or `default_weights`.
// Applied to the rest positions before skinning.
struct MorphTargets {
    uint32_t mesh = 0;
    std::vector<std::vector<Vec3f>> position_deltas;  // [target][vertex]
    std::vector<std::vector<Vec3f>> normal_deltas;    // empty, or [target][vertex]
    std::vector<float> default_weights;
    Track weights;
};

// Linear-blend skinning (glTF skins): vertex v = sum_j weight[v][j] *
// world(joints[joint[v][j]]) * inverse_bind[joint[v][j]] * rest(v). The
// result is in world space, so the instances of a skinned mesh should carry
// the identity (glTF ignores the skinned node's own transform).
struct Skin {
    uint32_t mesh = 0;
    std::vector<uint32_t> joints;           // indices into Animation::nodes
    std::vector<Affine3f> inverse_bind;     // one per joint
    std::vector<std::array<uint16_t, 4>> vertex_joints;  // per vertex, indices into `joints`
    std::vector<Vec4f> vertex_weights;      // per vertex, summing to 1
};

// The camera at time t: when `node` >= 0 the file's camera (eye, target,
// up) is moved by that node's world transform; any track with keys then
// replaces eye, target or up (width 3), or the vertical fov in degrees (width 1).
struct CameraAnimation {
    int32_t node = -1;
    Track eye, target, up, vfov_degrees;
    // The camera the node moves and the tracks replace (in the node's space);
    // when unset, Scene::finalize() takes Scene::camera (or the default).
    std::optional<Camera> rest;
};

struct Animation {
    float start = 0.0f, end = 0.0f;  // seconds covered by the keys (start == end: a still scene)
    float frames_per_second = 30.0f; // what `--frames` numbers count (BART: the file's frame rate)
    std::vector<AnimatedNode> nodes;
    std::vector<InstanceAnimation> instances;
    std::vector<VertexKeyframes> vertex_keyframes;
    std::vector<MorphTargets> morphs;
    std::vector<Skin> skins;
    std::optional<CameraAnimation> camera;
    // glTF: the clip that plays and the names of all the file's clips ("" for an unnamed one).
    std::string clip;
    std::vector<std::string> clips;
    // Object-space rest positions and normals of every mesh that morphs or
    // skinning deform (evaluation starts from them each time); filled by
    // Scene::finalize(). Indexed like Scene::meshes; empty for other meshes.
    std::vector<std::vector<Vec3f>> rest_positions, rest_normals;
    // Set by Scene::set_time: later calls report only what differs from the
    // scene as last evaluated (the first reports everything animated).
    bool evaluated = false;

    [[nodiscard]] bool empty() const {
        return instances.empty() && vertex_keyframes.empty() && morphs.empty() && skins.empty() && !camera;
    }
    [[nodiscard]] float duration() const { return end - start; }
    // The time of frame `frame` (frame 0 = start).
    [[nodiscard]] float frame_time(int frame) const { return start + float(frame) / frames_per_second; }
    [[nodiscard]] int frame_count() const;  // frames from start to end inclusive at frames_per_second
};

// A track's value at time t (`out` gets track.width floats; rotations come
// back as unit quaternions). Shared by every kind of animated property.
void evaluate_track(const Track& track, float t, float* out);

// What moved between two evaluations of a scene (Scene::set_time): the
// meshes whose positions changed (deformed) and the instances whose
// transform or visibility changed (moved rigidly, or a deformed mesh's
// instance). Both sorted ascending. Accels and renderers are told this.
struct GeometryChange {
    std::vector<uint32_t> meshes;
    std::vector<uint32_t> instances;
    bool camera = false;
    [[nodiscard]] bool geometry() const { return !meshes.empty() || !instances.empty(); }
};

}  // namespace rf
