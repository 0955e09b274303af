// Internal pieces of the animation evaluation (src/scene/animation.cpp) that
// the loaders share, so that every format evaluates its keys with one
// implementation.
#pragma once

#include "rayforge/scene/animation.h"

namespace rf {

struct Scene;

// evaluate_track with the meaning of a width-4 track made explicit: a
// rotation (slerp/squad, a unit quaternion out) or plain values (morph weights).
void evaluate_track(const Track& track, float t, float* out, bool rotation);

// The rotation matrix of quaternion x, y, z, w (normalised first; 0 gives the identity).
Affine3f quaternion_matrix(const float q[4]);

// BART's rotation key (axis, angle in radians) as a quaternion x, y, z, w; a zero axis is the identity.
Vec4f axis_angle_quaternion(double ax, double ay, double az, double radians);

// A node's local transform at time t: its matrix, or T * R * S from its rest values and tracks.
Affine3f node_local_transform(const AnimatedNode& node, float t);
// Its own visibility at time t (not its parents').
bool node_visible(const AnimatedNode& node, float t);

// Frames from start to end inclusive at `fps` (Animation::frame_count, TimeRange::frame_count).
int animation_frame_count(float start, float end, float fps);

// Scene::finalize's part: validates the animation (one-line rf::Error
// "animation: ...") and fills the rest positions, normals and camera.
void finalize_animation(Scene& scene);

}  // namespace rf
