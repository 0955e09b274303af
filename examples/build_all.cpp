// Builds the canonical BVH of a scene with every builder and prints each
// one's SAH cost, node count and build time (on a CUDA device, the builders
// without a device version say so).
//   build_all [SCENE] [DEVICE]     default builtin:spheres on cpu
#include <chrono>
#include <cstdio>
#include <string>

#include <rayforge/rayforge.h>

int main(int argc, char** argv) {
    const std::string scene_name = argc > 1 ? argv[1] : "builtin:spheres";
    try {
        const rf::SceneGeometry geometry = rf::SceneGeometry::build(rf::load_scene(scene_name));
        const rf::Device device = rf::parse_device(argc > 2 ? argv[2] : "cpu");
        std::printf("%s: %zu triangles, on %s\n", scene_name.c_str(), geometry.size(), rf::to_string(device).c_str());
        std::printf("%-14s %10s %10s %12s\n", "builder", "SAH", "nodes", "build ms");
        int built = 0;
        for (const char* name : {"binned", "sweep", "sbvh", "lbvh30", "lbvh63", "hlbvh2", "gridbvh", "gridbvh-split", "ploc"}) {
            rf::BuildOptions options;
            options.builder = rf::parse_builder(name);
            options.device = device;
            try {
                const auto start = std::chrono::steady_clock::now();
                rf::BuildReport report;
                const rf::Bvh bvh = rf::build_bvh(geometry.triangles, options, &report);
                const double ms =
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
                std::printf("%-14s %10.2f %10zu %12.2f%s\n", name, bvh.sah_cost(), bvh.nodes.size(), ms,
                            report.on_device ? "  (device)" : "");
                ++built;
            } catch (const rf::Error& e) {
                std::printf("%-14s %s\n", name, e.what());
            }
        }
        return built > 0 ? 0 : 1;
    } catch (const rf::Error& e) {
        std::fprintf(stderr, "build_all: error: %s\n", e.what());
        return 1;
    }
}
