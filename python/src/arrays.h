// NumPy arrays in and out of the engine: shapes and dtypes checked with a
// ValueError / TypeError naming the argument, inputs read in place when they
// are C-contiguous float32 (converted once otherwise), converted into the
// engine's layouts (Ray, Vec3f) in parallel without the GIL, outputs
// allocated once with the inputs' leading dimensions and returned as they
// are.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"

namespace rf::py {

namespace pyb = pybind11;

// A float32 array of shape (..., last): its data (in place when it was already
// C-contiguous float32) and its leading dimensions.
struct FloatRows {
    pyb::array_t<float, pyb::array::c_style> array;  // keeps the data alive
    std::vector<pyb::ssize_t> leading;                // shape without the last dimension
    size_t rows = 0;
    [[nodiscard]] const float* data() const { return array.data(); }
};

// `value` as rows of `last` floats: a ValueError for another shape, a
// TypeError for a non-numeric or integer dtype (float64 is converted).
FloatRows float_rows(const pyb::handle& value, int last, const char* name);

// (..., 6) rays [ox, oy, oz, dx, dy, dz] as engine rays with t in [tnear, tfar]
// (converted in parallel; call without the GIL). Non-finite rays are kept:
// they hit nothing.
std::vector<Ray> to_rays(const FloatRows& rays, float tnear, float tfar);
// (..., 3) points.
std::span<const Vec3f> as_points(const FloatRows& points);

// A C-contiguous output array of `leading` + `trailing` dimensions.
template <class T>
pyb::array_t<T> output(const std::vector<pyb::ssize_t>& leading, std::initializer_list<pyb::ssize_t> trailing = {}) {
    std::vector<pyb::ssize_t> shape = leading;
    shape.insert(shape.end(), trailing.begin(), trailing.end());
    return pyb::array_t<T>(shape);
}

// (n, 3) vertex positions: finite float32 (ValueError naming the first bad row).
std::vector<Vec3f> vertex_positions(const pyb::handle& value, const char* name);
// (m, 3) triangle indices below `vertex_count` (uint32, int32 or int64).
std::vector<uint32_t> triangle_indices(const pyb::handle& value, size_t vertex_count, const char* name);

// The engine's thread count for an `nthreads` argument (0 = all cores;
// negative: ValueError).
int thread_count(int nthreads);

}  // namespace rf::py
