// Renders progressively to a PNG, moving the camera half-way: the path
// tracer accumulates passes, a callback reports each one, the camera change
// restarts accumulation, and the final image is written.
//   progressive_render OUT.png [PASSES] [DEVICE]     default 16 passes on cpu
#include <cstdio>
#include <string>

#include <rayforge/rayforge.h>

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: progressive_render OUT.png [PASSES] [DEVICE]\n");
        return 2;
    }
    const std::string output = argv[1];
    const int passes = argc > 2 ? std::stoi(argv[2]) : 16;
    try {
        rf::WorldOptions world_options;
        world_options.device = rf::parse_device(argc > 3 ? argv[3] : "cpu");
        const auto world = rf::open_world("builtin:cornell", world_options);

        rf::RenderOptions options;
        options.width = 160;
        options.height = 120;
        options.integrator = rf::IntegratorKind::Path;
        options.spp = passes / 2 > 0 ? passes / 2 : 1;
        const rf::Camera camera = world->camera();
        const auto renderer = rf::make_renderer(*world, camera, options);

        const auto report = [](const rf::Renderer& r) {
            std::printf("pass %d: %.1f ms, %llu rays\n", r.passes(), r.last_pass().pass_ms,
                        static_cast<unsigned long long>(r.last_pass().closest_rays + r.last_pass().shadow_rays));
            return true;
        };
        rf::render_progressive(*renderer, report);

        // Half-way: the camera steps back and to the side; accumulation restarts.
        rf::Camera moved = camera;
        moved.eye = camera.eye + (camera.eye - camera.target) * 0.3f + rf::Vec3f(0.2f * rf::length(camera.eye - camera.target), 0.0f, 0.0f);
        renderer->set_camera(moved);
        std::printf("camera moved: %d passes accumulated\n", renderer->passes());
        rf::render_progressive(*renderer, report);

        rf::write_image(output, renderer->image());
        std::printf("wrote %s: %dx%d, %d passes since the camera moved, %.2f Mrays/s\n", output.c_str(),
                    options.width, options.height, renderer->passes(),
                    double(renderer->stats().rays()) / (renderer->stats().seconds * 1e6));
        return 0;
    } catch (const rf::Error& e) {
        std::fprintf(stderr, "progressive_render: error: %s\n", e.what());
        return 1;
    }
}
