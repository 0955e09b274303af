// OBJ geometry parser (rf::load_obj). Material libraries the input names are
// looked up next to it: t.ppm and the input itself are there.
#include "fuzz_common.h"
#include "rayforge/io/scene_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string path = rf::fuzz::write_scratch("input.obj", data, size);
    rf::fuzz::expect_success_or_rf_error([&] { (void)rf::load_obj(path); });
    return 0;
}
