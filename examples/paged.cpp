// Generates a small paged scene (.rfpack) with the library, opens it as a
// world whose page caches may hold about a tenth of its pages, renders it with the
// path tracer and prints what the caches did: a scene rendered from pages
// read on demand, larger than the memory it is given.
//   paged OUT.rfpack OUT.png [TRIANGLES]     default 200000 triangles
#include <cstdio>
#include <string>

#include <rayforge/rayforge.h>

int main(int argc, char** argv) {
    if (argc < 3) {
        std::fprintf(stderr, "usage: paged OUT.rfpack OUT.png [TRIANGLES]\n");
        return 2;
    }
    try {
        rf::GenerateOptions generate;
        generate.name = "terrain-statues";
        generate.triangles = argc > 3 ? std::stoull(argv[3]) : 200000;
        const rf::PagedWriteReport written = rf::generate_paged_scene(generate, argv[1]);
        std::printf("wrote %s: %llu triangles, %llu bytes\n", argv[1],
                    static_cast<unsigned long long>(written.triangles),
                    static_cast<unsigned long long>(written.file_bytes));

        rf::WorldOptions options;
        options.paged.memory_budget = written.decoded_bytes / 10;  // a tenth of the (decoded) pages
        const auto world = rf::open_world(argv[1], options);
        rf::RenderOptions render;
        render.width = 160;
        render.height = 120;
        render.spp = 2;
        render.integrator = rf::IntegratorKind::Path;
        rf::write_image(argv[2], rf::render(*world, world->camera(), render));

        std::printf("rendered %s from a budget of %llu bytes\n", argv[2],
                    static_cast<unsigned long long>(options.paged.memory_budget));
        for (const rf::PageCacheReport& c : world->paged_scene().caches())
            std::printf("  %s: %u of %u pages cached, %.1f%% hits, %llu pages read\n", c.name.c_str(), c.cached,
                        c.pages, 100.0 * c.hit_rate(), static_cast<unsigned long long>(c.pages_read));
        return 0;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "paged: error: %s\n", e.what());
        return 1;
    }
}
