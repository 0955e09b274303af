// Perspective camera with optional thin lens, and primary ray generation.
#pragma once

#include <string>

#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"

namespace rf {

struct Camera {
    Vec3f eye{0, 0, 5};
    Vec3f target{0, 0, 0};
    Vec3f up{0, 1, 0};
    float vfov_degrees = 45.0f;
    float aperture_radius = 0.0f;  // 0 = pinhole
    float focus_distance = 0.0f;   // 0 = distance from eye to target
};

// The camera's command-line form "ex,ey,ez,tx,ty,tz,ux,uy,uz,fov" (eye,
// target, up, vertical field of view in degrees): to_string writes it with
// enough digits to read back the same floats; parse_camera reads exactly
// ten finite comma-separated numbers (spaces after a number allowed) and
// throws rf::Error otherwise. Lens settings are not part of it.
std::string to_string(const Camera& camera);
Camera parse_camera(const std::string& text);

// Precomputed camera frame; generate() is per-ray code shared by both backends.
struct CameraFrame {
    Vec3f eye, forward, right, up;   // orthonormal basis, forward = view direction
    float tan_half_fov = 0.0f;
    float aspect = 1.0f;             // width / height
    float aperture_radius = 0.0f;
    float focus_distance = 1.0f;

    // Throws rf::Error for a degenerate camera (eye == target, up parallel to view, bad fov).
    static CameraFrame make(const Camera& camera, int width, int height);

    // Ray through film position (px, py) in pixels, (0,0) = top-left corner of the
    // image; lens_u, lens_v in [0,1) sample the aperture. Direction is normalised.
    RF_HD Ray generate(float px, float py, int width, int height,
                       float lens_u = 0.5f, float lens_v = 0.5f) const {
        float ndc_x = (2.0f * px / float(width) - 1.0f) * tan_half_fov * aspect;
        float ndc_y = (1.0f - 2.0f * py / float(height)) * tan_half_fov;
        Vec3f dir = forward + right * ndc_x + up * ndc_y;
        Ray ray;
        if (aperture_radius > 0.0f) {
            // Concentric-free polar mapping is enough for a thin lens.
            float r = aperture_radius * sqrtf(lens_u);
            float phi = 6.2831853f * lens_v;
            Vec3f lens = right * (r * cosf(phi)) + up * (r * sinf(phi));
            Vec3f focus_point = eye + dir * focus_distance;
            ray.org = eye + lens;
            ray.dir = normalize(focus_point - ray.org);
        } else {
            ray.org = eye;
            ray.dir = normalize(dir);
        }
        return ray;
    }
};

}  // namespace rf
