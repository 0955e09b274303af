// PLY parser (rf::load_ply): header, ascii and both binary bodies.
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string path = rf::fuzz::write_scratch("input.ply", data, size);
    rf::fuzz::expect_success_or_rf_error([&] { (void)rf::load_ply(path); });
    return 0;
}
