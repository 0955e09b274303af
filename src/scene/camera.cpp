#include "rayforge/scene/camera.h"

#include <cmath>

#include "rayforge/core/error.h"

namespace rf {

CameraFrame CameraFrame::make(const Camera& camera, int width, int height) {
    if (width <= 0 || height <= 0) throw Error("camera: image size must be positive");
    if (!is_finite(camera.eye) || !is_finite(camera.target) || !is_finite(camera.up))
        throw Error("camera: eye, target and up must be finite");
    if (!(camera.vfov_degrees > 0.0f && camera.vfov_degrees < 180.0f))
        throw Error("camera: vertical field of view must be in (0, 180) degrees");
    Vec3f view = camera.target - camera.eye;
    float distance = length(view);
    if (!(distance > 0.0f)) throw Error("camera: eye and target coincide");
    CameraFrame f;
    f.eye = camera.eye;
    f.forward = view / distance;
    Vec3f right = cross(f.forward, camera.up);
    if (!(length(right) > 1e-6f * length(camera.up))) throw Error("camera: up is parallel to the view direction");
    f.right = normalize(right);
    f.up = cross(f.right, f.forward);
    f.tan_half_fov = std::tan(0.5f * camera.vfov_degrees * 3.14159265358979f / 180.0f);
    f.aspect = float(width) / float(height);
    f.aperture_radius = camera.aperture_radius;
    f.focus_distance = camera.focus_distance > 0.0f ? camera.focus_distance : distance;
    if (f.aperture_radius < 0.0f) throw Error("camera: aperture radius must not be negative");
    return f;
}

}  // namespace rf
