// BART AFF parser (rf::load_aff): keywords, meshes, transforms, keyframes.
// Includes resolve next to the scratch file, so fuzzed include names mostly
// exercise the "no such file" path; the include logic has its own tests.
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string path = rf::fuzz::write_scratch("input.aff", data, size);
    rf::fuzz::expect_success_or_rf_error([&] {
        rf::Scene scene = rf::load_aff(path);
        scene.finalize();
        // Whatever loads animates without failing: set_time never throws, keeps the triangle count.
        const size_t triangles = scene.triangle_count();
        for (float t : {scene.animation.start, scene.animation.end, 0.5f * (scene.animation.start + scene.animation.end),
                        scene.animation.start - 1.0f, 1e30f})
            (void)scene.set_time(t);
        if (scene.triangle_count() != triangles) __builtin_trap();
    });
    return 0;
}
