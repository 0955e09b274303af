// Renders frames 0, 10 and 20 of a built-in animated scene to PNGs: one
// world moved through time with World::set_time (its structure follows by
// the update method) and one renderer that follows the world by itself. The
// same lines run on the CPU and on a CUDA device.
//   animate OUT_PREFIX [DEVICE] [SCENE]     default cpu, builtin:explode
#include <cstdio>
#include <string>

#include <rayforge/rayforge.h>

int main(int argc, char** argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: animate OUT_PREFIX [DEVICE] [SCENE]\n");
        return 2;
    }
    try {
        rf::WorldOptions options;
        options.device = rf::parse_device(argc > 2 ? argv[2] : "cpu");
        options.update.method = rf::UpdateMethod::Refit;
        const auto world = rf::open_world(argc > 3 ? argv[3] : "builtin:explode", options);
        rf::RenderOptions render;
        render.width = 160;
        render.height = 120;
        const auto renderer = rf::make_renderer(*world, world->camera(), render);
        for (int frame : {0, 10, 20}) {
            const rf::UpdateStats update = world->set_time(world->time_range().frame_time(frame));
            rf::render_progressive(*renderer);
            const std::string path = std::string(argv[1]) + std::to_string(frame) + ".png";
            rf::write_image(path, renderer->image());
            std::printf("frame %d: %s, update %.2f ms (%s on %s)\n", frame, path.c_str(), update.update_ms,
                        world->stats().update_method.c_str(), rf::to_string(world->device()).c_str());
        }
        return 0;
    } catch (const rf::Error& e) {
        std::fprintf(stderr, "animate: error: %s\n", e.what());
        return 1;
    }
}
