// BART AFF parser (rf::load_aff): keywords, meshes, transforms, keyframes.
// Includes resolve next to the scratch file, so fuzzed include names mostly
// exercise the "no such file" path; the include logic has its own tests.
#include "fuzz_animation.h"
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"
#include "rayforge/scene/scene.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string path = rf::fuzz::write_scratch("input.aff", data, size);
    rf::fuzz::expect_success_or_rf_error([&] {
        rf::Scene scene = rf::load_aff(path);
        scene.finalize();
        // Whatever loads animates consistently (fuzz_animation.h).
        rf::fuzz::trap_unless_animation_is_consistent(scene);
    });
    return 0;
}
