#include "rayforge/scene/camera.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <vector>

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

std::string to_string(const Camera& c) {
    const float values[10] = {c.eye.x, c.eye.y, c.eye.z, c.target.x, c.target.y, c.target.z,
                              c.up.x,  c.up.y,  c.up.z,  c.vfov_degrees};
    std::string text;
    for (float v : values) {
        char number[32];
        std::snprintf(number, sizeof number, "%.9g", double(v));  // 9 digits: any float reads back exactly
        if (!text.empty()) text += ',';
        text += number;
    }
    return text;
}

Camera parse_camera(const std::string& text) {
    std::vector<float> v;
    std::stringstream ss(text);
    std::string item;
    const Error malformed("camera: expected ex,ey,ez,tx,ty,tz,ux,uy,uz,fov (ten numbers), got '" + text + "'");
    while (std::getline(ss, item, ',')) {
        try {
            size_t used = 0;
            const float value = std::stof(item, &used);
            while (used < item.size() && item[used] == ' ') ++used;
            if (used != item.size() || !std::isfinite(value)) throw malformed;
            v.push_back(value);
        } catch (const std::logic_error&) {  // std::stof: not a number, or out of range
            throw malformed;
        }
    }
    if (v.size() != 10 || (!text.empty() && text.back() == ',')) throw malformed;
    Camera c;
    c.eye = {v[0], v[1], v[2]};
    c.target = {v[3], v[4], v[5]};
    c.up = {v[6], v[7], v[8]};
    c.vfov_degrees = v[9];
    return c;
}

}  // namespace rf
