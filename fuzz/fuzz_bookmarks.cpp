// The viewer's camera bookmarks file (apps/viewer/bookmarks.h): any bytes
// either parse into cameras that can render, or fail with one rf::Error; what
// parses survives a write and a second read unchanged.
#include "bookmarks.h"
#include "fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string text(reinterpret_cast<const char*>(data), size);
    rf::fuzz::expect_success_or_rf_error([&] {
        const rf::viewer::Bookmarks marks = rf::viewer::Bookmarks::parse(text, "fuzz.json");
        const rf::viewer::Bookmarks again = rf::viewer::Bookmarks::parse(marks.to_json(), "again.json");
        if (again.all().size() != marks.all().size()) std::abort();
        for (const rf::viewer::Bookmark& b : again.all()) (void)rf::CameraFrame::make(b.camera, 4, 4);
    });
    return 0;
}
