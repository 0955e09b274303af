// Loads a built-in scene, builds the default acceleration structure and
// traces one ray through the middle of the view: must hit.
#include <cstdio>

#include <rayforge/rayforge.h>

int main() {
    try {
        rf::Scene scene = rf::load_scene("builtin:cornell");
        rf::SceneGeometry geometry = rf::SceneGeometry::build(scene);
        auto accel = rf::build_accel(geometry);
        rf::Camera camera = scene.camera_or_default();
        rf::Ray ray{camera.eye, 0.0f, rf::normalize(camera.target - camera.eye), rf::kInfinity};
        rf::Hit hit = accel->intersect(ray);
        std::printf("triangles=%zu hit=%d t=%g\n", geometry.size(), int(hit.found()), double(hit.t));
        return hit.found() ? 0 : 1;
    } catch (const rf::Error& e) {
        std::fprintf(stderr, "consumer: error: %s\n", e.what());
        return 1;
    }
}
