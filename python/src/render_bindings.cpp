// rayforge.Renderer (a progressive renderer of a World) and rayforge.write_image.
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstring>
#include <memory>

#include "arrays.h"
#include "bindings.h"
#include "rayforge/io/image_io.h"
#include "rayforge/render/render.h"

namespace rf::py {
namespace {

// One keyword argument, named as the CLI option (max_depth for --max-depth).
void apply_option(RenderOptions& o, const std::string& k, const pyb::handle& value) {
    if (k == "width") o.width = value.cast<int>();
    else if (k == "height") o.height = value.cast<int>();
    else if (k == "spp") o.spp = value.cast<int>();
    else if (k == "integrator")
        o.integrator = parsed("integrator", [&] { return parse_integrator(value.cast<std::string>()); });
    else if (k == "threads") o.threads = thread_count(value.cast<int>());
    else if (k == "seed") o.seed = value.cast<uint32_t>();
    else if (k == "time_budget") o.time_budget_s = value.cast<double>();
    else if (k == "aovs") o.aovs = value.cast<bool>();
    else if (k == "max_depth") o.max_depth = value.cast<int>();
    else if (k == "rr_depth") o.rr_depth = value.cast<int>();
    else if (k == "light_sampling")
        o.light_sampling = parsed("light_sampling", [&] { return parse_light_sampling(value.cast<std::string>()); });
    else if (k == "clamp") o.max_sample_value = value.cast<float>();
    else if (k == "wavefront") o.wavefront = value.cast<bool>();
    else if (k == "sort_rays") o.sort_rays = value.cast<bool>();
    else if (k == "reflection_depth") o.reflection_depth = value.cast<int>();
    else if (k == "refraction_depth") o.refraction_depth = value.cast<int>();
    else if (k == "shading")
        o.whitted_shading = parsed("shading", [&] { return parse_whitted_shading(value.cast<std::string>()); });
    else if (k == "ao_radius") o.ao_radius = value.cast<float>();
    else if (k == "ao_samples") o.ao_samples = value.cast<int>();
    else
        throw pyb::type_error("Renderer: unknown option '" + k +
                              "' (width, height, spp, integrator, threads, seed, time_budget, aovs, max_depth, "
                              "rr_depth, light_sampling, clamp, wavefront, sort_rays, reflection_depth, "
                              "refraction_depth, shading, ao_radius, ao_samples)");
}

// RenderOptions from keyword arguments; an unknown key or a value of the
// wrong kind is a TypeError, a value out of range a ValueError.
void apply_options(RenderOptions& o, const pyb::kwargs& kwargs) {
    for (const auto& [key, value] : kwargs) {
        const std::string k = key.cast<std::string>();
        try {
            apply_option(o, k, value);
        } catch (const pyb::cast_error&) {
            throw pyb::type_error("Renderer: option '" + k + "' got a " +
                                  pyb::str(pyb::type::of(value)).cast<std::string>() + " of the wrong kind");
        }
    }
    parsed("options", [&] {
        validate_render_options(o);
        return 0;
    });
}

// An image as a float32 (height, width, 3) array (empty (0, 0, 3) when off).
pyb::array_t<float> to_array(const Image& image) {
    pyb::array_t<float> out({pyb::ssize_t(image.height), pyb::ssize_t(image.width), pyb::ssize_t(3)});
    float* o = out.mutable_data();
    for (size_t i = 0; i < image.pixels.size(); ++i) o[3 * i] = image.pixels[i].x, o[3 * i + 1] = image.pixels[i].y,
                                                     o[3 * i + 2] = image.pixels[i].z;
    return out;
}

// The renderer with its world kept alive (renderers share the world's state
// anyway; the reference keeps the Python object's lifetime obvious).
struct PyRenderer {
    std::shared_ptr<World> world;
    std::unique_ptr<Renderer> renderer;
};

}  // namespace

void bind_render(pyb::module_& m) {
    pyb::class_<PyRenderer>(m, "Renderer",
                            "A progressive renderer of a World on the world's device: each render_pass adds one "
                            "sample per pixel; the image is the mean. Options are the CLI's render options.")
        .def(pyb::init([](std::shared_ptr<World> world, const std::optional<Camera>& camera, const pyb::kwargs& kw) {
                 RenderOptions o;
                 apply_options(o, kw);
                 const Camera c = camera ? *camera : world->camera();
                 auto p = std::make_unique<PyRenderer>();
                 p->world = std::move(world);
                 pyb::gil_scoped_release release;
                 p->renderer = make_renderer(*p->world, c, o);
                 return p;
             }),
             pyb::arg("world"), pyb::arg("camera") = pyb::none())
        .def("render_pass",
             [](PyRenderer& r) {
                 pyb::gil_scoped_release release;
                 return r.renderer->render_pass();
             },
             "Adds one sample per pixel (the GIL is released meanwhile).")
        .def("render",
             [](PyRenderer& r) {
                 {
                     pyb::gil_scoped_release release;
                     render_progressive(*r.renderer);
                 }
                 return to_array(r.renderer->image());
             },
             "Runs passes until spp are done (or time_budget is spent) and returns the image.")
        .def_property_readonly("passes", [](const PyRenderer& r) { return r.renderer->passes(); },
                               "passes accumulated since the last restart")
        .def_property_readonly("device", [](const PyRenderer& r) { return to_string(r.renderer->device()); },
                               "where it renders: its world's device")
        .def("image", [](const PyRenderer& r) { return to_array(r.renderer->image()); },
             "The mean of the passes: float32 (height, width, 3), linear radiance.")
        .def("albedo", [](const PyRenderer& r) { return to_array(r.renderer->albedo()); }, "AOV (aovs=True)")
        .def("normal", [](const PyRenderer& r) { return to_array(r.renderer->normal()); }, "AOV (aovs=True)")
        .def("depth", [](const PyRenderer& r) { return to_array(r.renderer->depth()); }, "AOV (aovs=True)")
        .def("set_camera", [](PyRenderer& r, const Camera& c) { r.renderer->set_camera(c); }, pyb::arg("camera"),
             "A new camera; accumulation restarts.")
        .def("set_options",
             [](PyRenderer& r, const pyb::kwargs& kw) {
                 RenderOptions o = r.renderer->options();
                 apply_options(o, kw);
                 r.renderer->set_options(o);
             },
             "New options (the same keywords as the constructor); accumulation restarts.")
        .def("stats", [](const PyRenderer& r) {
            const RenderStats s = r.renderer->stats();
            pyb::dict d;
            d["samples"] = s.samples;
            d["closest_rays"] = s.closest_rays;
            d["shadow_rays"] = s.shadow_rays;
            d["seconds"] = s.seconds;
            return d;
        }, "samples, closest_rays, shadow_rays and seconds of the passes so far");

    m.def(
        "write_image",
        [](const std::string& path, const pyb::handle& image, float exposure, const std::string& tonemap) {
            const FloatRows rows = float_rows(image, 3, "image");
            if (rows.leading.size() != 2) throw pyb::value_error("image: expected an array of shape (height, width, 3)");
            Image img(int(rows.leading[1]), int(rows.leading[0]));
            const float* in = rows.data();
            for (size_t i = 0; i < rows.rows; ++i) img.pixels[i] = {in[3 * i], in[3 * i + 1], in[3 * i + 2]};
            const ToneMapping tone{exposure, parsed("tonemap", [&] { return parse_tone_curve(tonemap); })};
            pyb::gil_scoped_release release;
            write_image(path, img, tone);
        },
        pyb::arg("path"), pyb::arg("image"), pyb::kw_only(), pyb::arg("exposure") = 1.0f,
        pyb::arg("tonemap") = "clamp",
        "Writes a float (height, width, 3) image: .png (exposure, tone curve, sRGB), .exr or .pfm (linear).");
}

}  // namespace rf::py
