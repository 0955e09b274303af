#include "arrays.h"

#include <cmath>

#include "core/parallel.h"

namespace rf::py {
namespace {

std::string shape_text(const pyb::array& a) {
    std::string text = "(";
    for (pyb::ssize_t d = 0; d < a.ndim(); ++d) text += (d ? ", " : "") + std::to_string(a.shape(d));
    return text + (a.ndim() == 1 ? ",)" : ")");
}

std::string dtype_text(const pyb::array& a) { return pyb::str(a.dtype()).cast<std::string>(); }

pyb::array as_array(const pyb::handle& value, const char* name) {
    if (!pyb::isinstance<pyb::array>(value) && !pyb::isinstance<pyb::sequence>(value))
        throw pyb::type_error(std::string(name) + ": expected a numpy array, got " +
                              pyb::str(pyb::type::of(value)).cast<std::string>());
    return pyb::array::ensure(value);
}

}  // namespace

FloatRows float_rows(const pyb::handle& value, int last, const char* name) {
    const pyb::array a = as_array(value, name);
    if (!a) throw pyb::type_error(std::string(name) + ": not convertible to a numpy array");
    const char kind = a.dtype().kind();
    if (kind != 'f')
        throw pyb::type_error(std::string(name) + ": expected float32 values, got dtype " + dtype_text(a) +
                              (kind == 'i' || kind == 'u' ? " (convert with .astype(numpy.float32))" : ""));
    if (a.ndim() < 1 || a.shape(a.ndim() - 1) != last)
        throw pyb::value_error(std::string(name) + ": expected an array of shape (..., " + std::to_string(last) +
                               "), got " + shape_text(a));
    FloatRows rows;
    rows.array = pyb::array_t<float, pyb::array::c_style | pyb::array::forcecast>::ensure(a);  // in place for C-contiguous float32, else one C-side conversion
    if (!rows.array) throw pyb::type_error(std::string(name) + ": not convertible to float32");
    for (pyb::ssize_t d = 0; d + 1 < a.ndim(); ++d) rows.leading.push_back(a.shape(d));
    rows.rows = size_t(a.size()) / size_t(last);
    return rows;
}

RawArray<Ray> to_rays(const FloatRows& rays, float tnear, float tfar) {
    RawArray<Ray> out(rays.rows);
    const float* in = rays.data();
    parallel::for_range(size_t(0), rays.rows, size_t(4096), [&](size_t lo, size_t hi) {
        for (size_t i = lo; i < hi; ++i) {
            const float* r = in + 6 * i;
            out[i] = Ray{{r[0], r[1], r[2]}, tnear, {r[3], r[4], r[5]}, tfar};
        }
    });
    return out;
}

std::span<const Vec3f> as_points(const FloatRows& points) {
    static_assert(sizeof(Vec3f) == 3 * sizeof(float), "Vec3f must be three packed floats");
    return {reinterpret_cast<const Vec3f*>(points.data()), points.rows};
}

std::vector<Vec3f> vertex_positions(const pyb::handle& value, const char* name) {
    const FloatRows rows = float_rows(value, 3, name);
    if (rows.leading.size() != 1)
        throw pyb::value_error(std::string(name) + ": expected an array of shape (n, 3)");
    const std::span<const Vec3f> points = as_points(rows);
    for (size_t i = 0; i < points.size(); ++i)
        if (!std::isfinite(points[i].x) || !std::isfinite(points[i].y) || !std::isfinite(points[i].z))
            throw pyb::value_error(std::string(name) + ": row " + std::to_string(i) + " is not finite");
    return {points.begin(), points.end()};
}

std::vector<uint32_t> triangle_indices(const pyb::handle& value, size_t vertex_count, const char* name) {
    const pyb::array a = as_array(value, name);
    const char kind = a.dtype().kind();
    if (a.size() > 0 && kind != 'i' && kind != 'u')
        throw pyb::type_error(std::string(name) + ": expected integer indices (uint32, int32, int64), got dtype " +
                              dtype_text(a));
    if (a.ndim() != 2 || a.shape(1) != 3)
        throw pyb::value_error(std::string(name) + ": expected an array of shape (m, 3), got " + shape_text(a));
    const auto indices = pyb::array_t<int64_t, pyb::array::c_style | pyb::array::forcecast>::ensure(a);
    std::vector<uint32_t> out(size_t(indices.size()));
    const int64_t* in = indices.data();
    for (size_t i = 0; i < out.size(); ++i) {
        if (in[i] < 0 || uint64_t(in[i]) >= vertex_count)
            throw pyb::value_error(std::string(name) + ": triangle " + std::to_string(i / 3) + " has index " +
                                   std::to_string(in[i]) + ", not below the vertex count " +
                                   std::to_string(vertex_count));
        out[i] = uint32_t(in[i]);
    }
    return out;
}

int thread_count(int nthreads) {
    if (nthreads < 0) throw pyb::value_error("nthreads: expected 0 (all cores) or a positive count, got " +
                                             std::to_string(nthreads));
    return nthreads;
}

}  // namespace rf::py
