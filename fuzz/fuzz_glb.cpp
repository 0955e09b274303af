// glTF loader (rf::load_gltf) on .glb input. External URIs resolve in
// the scratch directory, which holds buf.bin (a quad's worth of floats) and
// t.ppm, so buffer and image references can succeed. What loads is then
// animated under fuzz_animation.h's checks (Scene::set_time at many times).
#include "fuzz_animation.h"
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    rf::fuzz::write_scratch_gltf_files();
    const std::string path = rf::fuzz::write_scratch("input.glb", data, size);
    rf::fuzz::expect_success_or_rf_error([&] {
        rf::Scene scene = rf::load_gltf(path);
        // Animations, skins and morphs evaluated consistently (fuzz_animation.h).
        rf::fuzz::trap_unless_animation_is_consistent(scene);
    });
    return 0;
}
