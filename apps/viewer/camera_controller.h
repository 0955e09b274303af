// The viewer's camera: what mouse, keyboard and script commands do to an
// rf::Camera. Orbit turns the eye about the target, look turns the view
// about the eye, pan slides both across the view, dolly moves the eye
// towards the target, walk moves both through the scene at a speed scaled
// to its size. "Up" is the start camera's up vector throughout, and the
// view never tips over it. No window is involved, so the tests drive it
// directly.
#pragma once

#include "rayforge/scene/camera.h"

namespace rf::viewer {

enum class WalkDirection { Forward, Back, Left, Right, Up, Down };
// "forward", "back", "left", "right", "up", "down"; rf::Error otherwise.
WalkDirection parse_walk_direction(const std::string& name);

class CameraController {
public:
    // `home` is where R returns (rf::Error when it cannot render); `scene_size` (the bounds' diagonal) sets
    // the walking speed and the closest the eye may come to the target.
    CameraController(const Camera& home, float scene_size);

    [[nodiscard]] const Camera& camera() const { return camera_; }
    void set(const Camera& camera);  // throws rf::Error for a camera that cannot render (CameraFrame::make)
    void reset() { camera_ = home_; }

    // Each motion returns false, leaving the camera as it was, when it would
    // make a camera that cannot render (huge steps overflowing to infinity).
    // Degrees; positive yaw moves the eye to its right, positive pitch up.
    bool orbit(float yaw_degrees, float pitch_degrees);
    // Degrees; positive yaw turns the view right, positive pitch up.
    bool look(float yaw_degrees, float pitch_degrees);
    // Pixels of an image `viewport_height` pixels tall: the point under the
    // cursor follows it (positive dx moves the view content right).
    bool pan(float dx_pixels, float dy_pixels, int viewport_height);
    // Wheel steps; each positive step takes the eye 15% closer to the target.
    bool dolly(float steps);
    // `seconds` of walking in `direction`, four times faster when `fast`.
    bool walk(WalkDirection direction, float seconds, bool fast);
    bool set_fov(float degrees);  // clamped to [5, 150]

    // Scene-size units per second of walking (`fast` not applied).
    [[nodiscard]] float walk_speed() const { return walk_speed_; }
    void set_walk_speed(float units_per_second);

private:
    [[nodiscard]] Vec3f world_up() const;
    bool accept(const Camera& candidate);
    Camera home_, camera_;
    float scene_size_;
    float walk_speed_;
};

}  // namespace rf::viewer
