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
#include <cstdlib>
#include <memory>
#include <new>
#include <span>
#include <type_traits>
#include <string>
#include <vector>

#include "rayforge/math/ray.h"
#include "rayforge/math/vec.h"

namespace rf::py {

namespace pyb = pybind11;

// An uninitialised array of a trivially copyable T (malloc'd storage, where
// such objects begin their lifetime when written): its users fill every
// element in parallel, so its pages are first touched in parallel too,
// not by std::vector's serial value-initialisation (a measured 10 % of a
// 1M-ray cast_rays on 2 cores).
template <class T>
class RawArray {
    static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>);

public:
    explicit RawArray(size_t size) : data_(static_cast<T*>(std::malloc((size > 0 ? size : 1) * sizeof(T)))), size_(size) {
        if (!data_) throw std::bad_alloc();
    }
    [[nodiscard]] T* data() { return data_.get(); }
    [[nodiscard]] const T* data() const { return data_.get(); }
    [[nodiscard]] size_t size() const { return size_; }
    T& operator[](size_t i) { return data_.get()[i]; }
    const T& operator[](size_t i) const { return data_.get()[i]; }
    operator std::span<T>() { return {data(), size_}; }
    operator std::span<const T>() const { return {data(), size_}; }

private:
    struct Free {
        void operator()(T* p) const { std::free(p); }
    };
    std::unique_ptr<T, Free> data_;
    size_t size_;
};

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
RawArray<Ray> to_rays(const FloatRows& rays, float tnear, float tfar);
// (..., 3) points.
std::span<const Vec3f> as_points(const FloatRows& points);

// A C-contiguous output array of `leading` + `trailing` dimensions.
template <class T>
pyb::array_t<T> output(const std::vector<pyb::ssize_t>& leading, std::initializer_list<pyb::ssize_t> trailing = {}) {
    std::vector<pyb::ssize_t> shape = leading;
    shape.insert(shape.end(), trailing.begin(), trailing.end());
    return pyb::array_t<T>(shape);
}

// A bool output's bytes, for the engine's 0/1 uint8_t answers: numpy's bool
// is one byte holding 0 or 1.
inline std::span<uint8_t> bool_bytes(pyb::array_t<bool>& out) {
    static_assert(sizeof(bool) == 1);
    return {reinterpret_cast<uint8_t*>(out.mutable_data()), size_t(out.size())};
}

// (n, 3) vertex positions: finite float32 (ValueError naming the first bad row).
std::vector<Vec3f> vertex_positions(const pyb::handle& value, const char* name);
// (m, 3) triangle indices below `vertex_count` (uint32, int32 or int64).
std::vector<uint32_t> triangle_indices(const pyb::handle& value, size_t vertex_count, const char* name);

// The engine's thread count for an `nthreads` argument (0 = all cores;
// negative: ValueError).
int thread_count(int nthreads);

}  // namespace rf::py
