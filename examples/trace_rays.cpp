// Traces a batch of rays through a world and prints hit statistics: camera
// rays through every pixel of a small image, then a shadow ray from each hit
// towards a point above the scene, all through the batch interface.
//   trace_rays [SCENE] [DEVICE]     default builtin:cornell on cpu; DEVICE: cpu, cuda, cuda:N
#include <cstdio>
#include <string>
#include <vector>

#include <rayforge/rayforge.h>

int main(int argc, char** argv) {
    const std::string scene_name = argc > 1 ? argv[1] : "builtin:cornell";
    try {
        rf::WorldOptions options;
        options.device = rf::parse_device(argc > 2 ? argv[2] : "cpu");
        const auto world = rf::open_world(scene_name, options);

        const int width = 160, height = 120;
        const rf::CameraFrame camera = rf::CameraFrame::make(world->camera(), width, height);
        std::vector<rf::Ray> rays;
        for (int y = 0; y < height; ++y)
            for (int x = 0; x < width; ++x) rays.push_back(camera.generate(x + 0.5f, y + 0.5f, width, height));
        std::vector<rf::Hit> hits(rays.size());
        world->intersect(rays, hits);

        // From every hit, a shadow ray to a point above the middle of the scene.
        const rf::Box3f bounds = world->bounds();
        const rf::Vec3f light = bounds.center() + rf::Vec3f(0.0f, 0.45f * bounds.extent().y, 0.0f);
        std::vector<rf::Ray> shadows;
        double t_sum = 0.0;
        for (size_t i = 0; i < rays.size(); ++i) {
            if (!hits[i].found()) continue;
            t_sum += hits[i].t;
            const rf::Vec3f p = rays[i].org + rays[i].dir * hits[i].t;
            const rf::Vec3f to_light = light - p;
            const float distance = rf::length(to_light);
            shadows.push_back(rf::Ray{p, 1e-3f * distance, to_light / distance, 0.999f * distance});
        }
        std::vector<uint8_t> blocked(shadows.size());
        world->occluded(shadows, blocked);
        size_t lit = 0;
        for (uint8_t b : blocked) lit += b ? 0 : 1;

        const size_t hit_count = shadows.size();
        const rf::WorldStats stats = world->stats();
        std::printf("%s on %s (%s): %llu triangles\n", scene_name.c_str(), rf::to_string(world->device()).c_str(),
                    stats.accel.name.c_str(), static_cast<unsigned long long>(stats.triangles));
        std::printf("camera rays: %zu, hits: %zu (%.1f%%), mean hit distance %.3f\n", rays.size(), hit_count,
                    100.0 * double(hit_count) / double(rays.size()), hit_count ? t_sum / double(hit_count) : 0.0);
        std::printf("shadow rays: %zu, reaching the light: %zu (%.1f%%)\n", shadows.size(), lit,
                    shadows.empty() ? 0.0 : 100.0 * double(lit) / double(shadows.size()));
        return hit_count > 0 ? 0 : 1;
    } catch (const rf::Error& e) {
        std::fprintf(stderr, "trace_rays: error: %s\n", e.what());
        return 1;
    }
}
