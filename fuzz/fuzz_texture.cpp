// Texture decoding from memory (rf::load_texture_from_memory): PNG, JPEG,
// TGA, BMP, PNM, HDR (stb_image) and EXR (tinyexr), chosen by content.
#include "fuzz_common.h"
#include "rayforge/io/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    rf::fuzz::expect_success_or_rf_error([&] {
        (void)rf::load_texture_from_memory(data, size, "fuzz-texture", rf::TextureEncoding::Srgb8);
    });
    return 0;
}
