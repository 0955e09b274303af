// glTF loader (rf::load_gltf) on .gltf input. External URIs resolve in
// the scratch directory, which holds buf.bin (a quad's worth of floats) and
// t.ppm, so buffer and image references can succeed.
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    static const bool files = [] {
        rf::fuzz::write_scratch_texture();
        const float quad[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
        const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
        std::string bin(reinterpret_cast<const char*>(quad), sizeof quad);
        bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
        rf::fuzz::write_scratch("buf.bin", bin);
        return true;
    }();
    (void)files;
    const std::string path = rf::fuzz::write_scratch("input.gltf", data, size);
    rf::fuzz::expect_success_or_rf_error([&] { (void)rf::load_gltf(path); });
    return 0;
}
