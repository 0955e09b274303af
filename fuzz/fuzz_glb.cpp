// glTF loader (rf::load_gltf) on .glb input. External URIs resolve in
// the scratch directory, which holds buf.bin (a quad's worth of floats) and
// t.ppm, so buffer and image references can succeed. What loads is then
// evaluated at a few times (Scene::set_time).
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    rf::fuzz::write_scratch_gltf_files();
    const std::string path = rf::fuzz::write_scratch("input.glb", data, size);
    rf::fuzz::expect_success_or_rf_error([&] {
        rf::Scene scene = rf::load_gltf(path);
        // Animations, skins and morphs: evaluated before, inside and after
        // the keys, and backwards.
        const float start = scene.animation.start, end = scene.animation.end;
        for (float t : {start - 1.0f, 0.5f * (start + end), end, end + 1e6f, start})
            (void)scene.set_time(t);
    });
    return 0;
}
