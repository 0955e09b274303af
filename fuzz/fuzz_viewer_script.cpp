// The viewer's script language (apps/viewer/script.h): any bytes either parse
// or fail with one rf::Error. Parsed camera motions are then applied to a
// controller, whose motions refuse steps that would overflow the camera.
#include "camera_controller.h"
#include "fuzz_common.h"
#include "script.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    rf::fuzz::init_once();
    const std::string text(reinterpret_cast<const char*>(data), size);
    rf::fuzz::expect_success_or_rf_error([&] {
        const rf::viewer::Script script = rf::viewer::parse_script(text, "fuzz.txt");
        rf::viewer::CameraController camera(rf::Camera{}, 10.0f);
        for (const rf::viewer::ScriptCommand& c : script.commands) {
            switch (c.op) {
                case rf::viewer::ScriptOp::Orbit: (void)camera.orbit(float(c.a), float(c.b)); break;
                case rf::viewer::ScriptOp::Look: (void)camera.look(float(c.a), float(c.b)); break;
                case rf::viewer::ScriptOp::Pan: (void)camera.pan(float(c.a), float(c.b), 360); break;
                case rf::viewer::ScriptOp::Dolly: (void)camera.dolly(float(c.a)); break;
                case rf::viewer::ScriptOp::Fov: (void)camera.set_fov(float(c.a)); break;
                case rf::viewer::ScriptOp::Walk:
                    (void)camera.walk(rf::viewer::parse_walk_direction(c.word), float(c.a), c.fast);
                    break;
                case rf::viewer::ScriptOp::Camera: camera.set(rf::parse_camera(c.rest)); break;
                default: break;
            }
            (void)rf::CameraFrame::make(camera.camera(), 4, 4);  // whatever happened, the camera still renders
        }
    });
    return 0;
}
