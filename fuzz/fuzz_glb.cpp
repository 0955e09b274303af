// glTF loader (rf::load_gltf) on .glb input. External URIs resolve in
// the scratch directory, which holds buf.bin (a quad's worth of floats) and
// t.ppm, so buffer and image references can succeed.
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    rf::fuzz::write_scratch_gltf_files();
    const std::string path = rf::fuzz::write_scratch("input.glb", data, size);
    rf::fuzz::expect_success_or_rf_error([&] { (void)rf::load_gltf(path); });
    return 0;
}
