// JSON scene format (rf::load_json_scene). Referenced files resolve in the
// scratch directory: m.obj, m.ply and t.ppm exist there, so references can
// succeed and merging is exercised; builtin: scenes need no file.
#include "fuzz_animation.h"
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    static const bool files = [] {
        rf::fuzz::write_scratch_texture();
        rf::fuzz::write_scratch("m.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
        rf::fuzz::write_scratch("m.ply",
                                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        return true;
    }();
    (void)files;
    const std::string path = rf::fuzz::write_scratch("input.json", data, size);
    rf::fuzz::expect_success_or_rf_error([&] {
        rf::Scene scene = rf::load_json_scene(path);
        scene.finalize();
        // Whatever loads animates consistently (fuzz_animation.h).
        rf::fuzz::trap_unless_animation_is_consistent(scene);
    });
    return 0;
}
