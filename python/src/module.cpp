// The extension module `rayforge._rayforge`, imported by the package
// `rayforge` (python/rayforge/__init__.py): the engine's public API
// (include/rayforge/) for Python. rf::Error becomes rayforge.Error with the
// same one-line message; bad arguments are ValueError / TypeError naming the
// argument. See docs/python.md.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "bindings.h"
#include "device_arrays.h"
#include "rayforge/backend/device.h"

namespace pyb = pybind11;

PYBIND11_MODULE(_rayforge, m) {
    m.doc() = "rayforge: a ray tracing engine for large scenes on CPUs and NVIDIA GPUs (docs/python.md).";
    m.attr("__version__") = RAYFORGE_VERSION;
    pyb::register_exception<rf::Error>(m, "Error", PyExc_RuntimeError).doc() =
        "An error of the engine (a file, an option, a budget, a device): its message is one line.";
    m.def("cuda_backend_built", &rf::cuda_backend_built, "Whether this build contains the CUDA backend.");
    m.def(
        "devices",
        [] {
            const rf::DeviceListing listing = rf::list_cuda_devices();
            pyb::list devices;
            devices.append("cpu");
            for (const rf::DeviceInfo& d : listing.devices) devices.append("cuda:" + std::to_string(d.index));
            return devices;
        },
        "The devices this process can use: 'cpu', then 'cuda:N' for each CUDA device.");
    rf::py::bind_camera(m);
    rf::py::bind_world(m);
    rf::py::bind_render(m);
    rf::py::bind_raycasting_scene(m);
    rf::py::bind_device_buffer(m);
}
