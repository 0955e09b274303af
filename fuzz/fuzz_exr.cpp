// OpenEXR decoding only (tinyexr behind rf::load_texture_from_memory): inputs
// without the EXR magic number are skipped, so every execution reaches tinyexr.
#include "fuzz_common.h"
#include "rayforge/io/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    if (size < 4 || data[0] != 0x76 || data[1] != 0x2f || data[2] != 0x31 || data[3] != 0x01) return -1;
    rf::fuzz::expect_success_or_rf_error([&] {
        (void)rf::load_texture_from_memory(data, size, "fuzz.exr", rf::TextureEncoding::LinearFloat);
    });
    return 0;
}
