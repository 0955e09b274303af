#include "camera_controller.h"

#include <algorithm>
#include <cmath>

#include "rayforge/core/error.h"

namespace rf::viewer {
namespace {

constexpr float kPi = 3.14159265358979f;
constexpr float kMinElevation = 1.0f * kPi / 180.0f;  // the view stays a degree away from straight up or down

float radians(float degrees) { return degrees * kPi / 180.0f; }

// `v` turned by `angle` radians about the unit axis `axis` (Rodrigues).
Vec3f rotate(Vec3f v, Vec3f axis, float angle) {
    const float c = std::cos(angle), s = std::sin(angle);
    return v * c + cross(axis, v) * s + axis * (dot(axis, v) * (1.0f - c));
}

// `dir` tilted by `pitch` radians towards `up`, its angle to `up` kept in
// [kMinElevation, pi - kMinElevation].
Vec3f tilt(Vec3f dir, Vec3f up, float pitch) {
    const float length_dir = length(dir);
    const Vec3f unit = dir / length_dir;
    const float angle = std::acos(std::clamp(dot(unit, up), -1.0f, 1.0f));  // 0 = straight up
    const float wanted = std::clamp(angle - pitch, kMinElevation, kPi - kMinElevation);
    Vec3f side = cross(unit, up);
    if (!(length(side) > 1e-6f)) return dir;  // already straight up or down: leave it
    side = normalize(side);
    return rotate(dir, side, angle - wanted) * (length_dir / length(dir));
}

}  // namespace

WalkDirection parse_walk_direction(const std::string& name) {
    if (name == "forward") return WalkDirection::Forward;
    if (name == "back") return WalkDirection::Back;
    if (name == "left") return WalkDirection::Left;
    if (name == "right") return WalkDirection::Right;
    if (name == "up") return WalkDirection::Up;
    if (name == "down") return WalkDirection::Down;
    throw Error("unknown walk direction '" + name + "' (expected forward, back, left, right, up or down)");
}

CameraController::CameraController(const Camera& home, float scene_size)
    : scene_size_(scene_size > 0.0f && std::isfinite(scene_size) ? scene_size : 1.0f),
      walk_speed_(0.2f * scene_size_) {
    set(home);
    home_ = home;
}

void CameraController::set(const Camera& camera) {
    (void)CameraFrame::make(camera, 1, 1);  // throws for a camera that cannot render
    camera_ = camera;
}

void CameraController::set_walk_speed(float units_per_second) {
    if (std::isfinite(units_per_second) && units_per_second > 0.0f) walk_speed_ = units_per_second;
}

Vec3f CameraController::world_up() const { return normalize(home_.up); }

bool CameraController::accept(const Camera& candidate) {
    try {
        (void)CameraFrame::make(candidate, 1, 1);
    } catch (const Error&) {
        return false;
    }
    camera_ = candidate;
    return true;
}

bool CameraController::orbit(float yaw_degrees, float pitch_degrees) {
    const Vec3f up = world_up();
    Camera c = camera_;
    Vec3f offset = c.eye - c.target;
    offset = rotate(offset, up, radians(yaw_degrees));
    // The eye rises when the view direction (-offset) tilts down.
    offset = -tilt(-offset, up, -radians(pitch_degrees));
    c.eye = c.target + offset;
    c.up = up;
    return accept(c);
}

bool CameraController::look(float yaw_degrees, float pitch_degrees) {
    const Vec3f up = world_up();
    Camera c = camera_;
    Vec3f dir = c.target - c.eye;
    dir = rotate(dir, up, -radians(yaw_degrees));
    dir = tilt(dir, up, radians(pitch_degrees));
    c.target = c.eye + dir;
    c.up = up;
    return accept(c);
}

bool CameraController::pan(float dx_pixels, float dy_pixels, int viewport_height) {
    const CameraFrame frame = CameraFrame::make(camera_, 1, 1);
    const float distance = length(camera_.target - camera_.eye);
    const float per_pixel = 2.0f * distance * frame.tan_half_fov / float(std::max(viewport_height, 1));
    const Vec3f shift = frame.right * (-dx_pixels * per_pixel) + frame.up * (dy_pixels * per_pixel);
    Camera c = camera_;
    c.eye += shift;
    c.target += shift;
    return accept(c);
}

bool CameraController::dolly(float steps) {
    const Vec3f offset = camera_.eye - camera_.target;
    const float distance = length(offset);
    const float wanted = std::max(distance * std::pow(0.85f, steps), 1e-4f * scene_size_);
    Camera c = camera_;
    c.eye = c.target + offset * (wanted / distance);
    return accept(c);
}

bool CameraController::walk(WalkDirection direction, float seconds, bool fast) {
    const CameraFrame frame = CameraFrame::make(camera_, 1, 1);
    const float step = walk_speed_ * (fast ? 4.0f : 1.0f) * seconds;
    Vec3f along{0.0f};
    switch (direction) {
        case WalkDirection::Forward: along = frame.forward; break;
        case WalkDirection::Back: along = -frame.forward; break;
        case WalkDirection::Right: along = frame.right; break;
        case WalkDirection::Left: along = -frame.right; break;
        case WalkDirection::Up: along = world_up(); break;
        case WalkDirection::Down: along = -world_up(); break;
    }
    Camera c = camera_;
    c.eye += along * step;
    c.target += along * step;
    return accept(c);
}

bool CameraController::set_fov(float degrees) {
    if (!std::isfinite(degrees)) return false;
    Camera c = camera_;
    c.vfov_degrees = std::clamp(degrees, 5.0f, 150.0f);
    return accept(c);
}

}  // namespace rf::viewer
