// AFF spheres (s) and cones (c), tessellated into loose triangles:
// kSphereStacks x kSphereSlices per sphere, 2 x kConeSegments per cone.
#include <cmath>
#include <utility>

#include "io/aff/aff_parser.h"

namespace rf::io::aff {

// s center.x center.y center.z radius (negative radius: inside visible)
void AffParser::parse_sphere(long line) {
    const Vec3f c = in().read_vec3("sphere center");
    const float r = in().read_float("sphere radius");
    if (r == 0.0f) {
        ++skipped_primitives_;
        return;
    }
    (void)line;
    const uint32_t material = material_index("");
    const float radius = std::fabs(r);
    auto point = [&](int stack, int slice) {
        const double theta = kPi * stack / kSphereStacks, phi = 2 * kPi * slice / kSphereSlices;
        return Vec3f{float(std::sin(theta) * std::cos(phi)), float(std::cos(theta)), float(std::sin(theta) * std::sin(phi))};
    };
    for (int i = 0; i < kSphereStacks; ++i) {
        for (int j = 0; j < kSphereSlices; ++j) {
            const Vec3f a = point(i, j), b = point(i + 1, j), cc = point(i + 1, j + 1), d = point(i, j + 1);
            auto emit = [&](Vec3f u, Vec3f v, Vec3f w) {
                Vec3f p[3] = {c + u * radius, c + v * radius, c + w * radius};
                Vec3f nn[3] = {u, v, w};
                if (r < 0) {
                    std::swap(p[1], p[2]);
                    nn[0] = -u; nn[1] = -w; nn[2] = -v;
                }
                add_triangle(p, nn, nullptr, material);
            };
            if (i != 0) emit(a, d, b);                  // outward winding (counter-clockwise seen from outside)
            if (i != kSphereStacks - 1) emit(b, d, cc);
        }
    }
    ++spheres_;
}

// c base.xyz base_radius apex.xyz apex_radius: an open cone or cylinder.
void AffParser::parse_cone(long line) {
    (void)line;
    const Vec3f base = in().read_vec3("cone base");
    const float r0 = std::fabs(in().read_float("cone base radius"));
    const Vec3f apex = in().read_vec3("cone apex");
    const float r1 = std::fabs(in().read_float("cone apex radius"));
    const Vec3f axis_v = apex - base;
    const float h = length(axis_v);
    if (!(h > 0.0f) || (r0 == 0.0f && r1 == 0.0f)) {
        ++skipped_primitives_;
        return;
    }
    const Vec3f axis = axis_v / h;
    const Vec3f helper = std::fabs(axis.x) < 0.9f ? Vec3f{1, 0, 0} : Vec3f{0, 1, 0};
    const Vec3f u = normalize(cross(axis, helper));
    const Vec3f v = cross(axis, u);
    const uint32_t material = material_index("");
    auto radial = [&](int s) {
        const double phi = 2 * kPi * s / kConeSegments;
        return u * float(std::cos(phi)) + v * float(std::sin(phi));
    };
    for (int s = 0; s < kConeSegments; ++s) {
        const Vec3f d0 = radial(s), d1 = radial(s + 1);
        const Vec3f n0 = normalize(d0 * h + axis * (r0 - r1)), n1 = normalize(d1 * h + axis * (r0 - r1));
        const Vec3f b0 = base + d0 * r0, b1 = base + d1 * r0, a0 = apex + d0 * r1, a1 = apex + d1 * r1;
        const Vec3f p1[3] = {b0, b1, a1}, q1[3] = {n0, n1, n1};
        const Vec3f p2[3] = {b0, a1, a0}, q2[3] = {n0, n1, n0};
        add_triangle(p1, q1, nullptr, material);
        add_triangle(p2, q2, nullptr, material);
    }
    ++cones_;
}

}  // namespace rf::io::aff
