#include "device_arrays.h"

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include <cstring>
#include <string>

#include "arrays.h"
#include "rayforge/world.h"

#if __has_include(<dlpack/dlpack.h>)
#include <dlpack/dlpack.h>
#define RF_PY_DLPACK 1
#endif

#if RAYFORGE_PY_CUDA
#include "backend/cuda/self_test.h"
#endif

namespace rf::py {
namespace {

std::string shape_text(const std::vector<int64_t>& shape) {
    std::string text = "(";
    for (size_t d = 0; d < shape.size(); ++d) text += (d ? ", " : "") + std::to_string(shape[d]);
    return text + (shape.size() == 1 ? ",)" : ")");
}

// Whether `strides` (in bytes; empty: C-contiguous by definition) are C-contiguous for `shape`.
bool c_contiguous(const std::vector<int64_t>& shape, const std::vector<int64_t>& strides, int item_bytes) {
    int64_t expected = item_bytes;
    for (size_t d = shape.size(); d-- > 0;) {
        if (shape[d] != 1 && !strides.empty() && strides[d] != expected) return false;
        expected *= shape[d];
    }
    return true;
}

// __cuda_array_interface__: a dict of shape, typestr ('<f4'), data (pointer,
// read-only), strides (None: C order), mask (must be None), stream (v3).
DeviceArray from_cuda_array_interface(const pyb::handle& value, const char* name, bool writable) {
    const std::string what = std::string(name) + ": __cuda_array_interface__ ";
    pyb::dict cai;
    try {
        cai = value.attr("__cuda_array_interface__").cast<pyb::dict>();
    } catch (const pyb::error_already_set&) {
        throw pyb::type_error(what + "could not be read");
    } catch (const pyb::cast_error&) {
        throw pyb::type_error(what + "is not a dict");
    }
    DeviceArray a;
    std::vector<int64_t> strides;
    try {
        a.shape = cai["shape"].cast<std::vector<int64_t>>();
        const std::string typestr = cai["typestr"].cast<std::string>();
        if (typestr.size() < 3 || (typestr[0] != '<' && typestr[0] != '|' && typestr[0] != '='))
            throw pyb::type_error(what + "typestr '" + typestr + "' is not a little-endian scalar type");
        a.kind = typestr[1];
        a.item_bytes = std::stoi(typestr.substr(2));
        const auto data = cai["data"].cast<std::pair<uintptr_t, bool>>();
        a.data = reinterpret_cast<void*>(data.first);
        if (writable && data.second) throw pyb::value_error(std::string(name) + ": the array is read-only");
        if (cai.contains("strides") && !cai["strides"].is_none()) strides = cai["strides"].cast<std::vector<int64_t>>();
        if (cai.contains("mask") && !cai["mask"].is_none())
            throw pyb::value_error(std::string(name) + ": masked device arrays are not supported");
        if (cai.contains("stream") && !cai["stream"].is_none()) a.stream = cai["stream"].cast<intptr_t>();
    } catch (const pyb::cast_error&) {
        throw pyb::type_error(what + "has a malformed shape, typestr, data, strides or stream");
    } catch (const std::invalid_argument&) {
        throw pyb::type_error(what + "has a malformed typestr");
    } catch (const std::out_of_range&) {
        throw pyb::type_error(what + "has a malformed typestr");
    }
    if (a.stream && *a.stream == 0)
        throw pyb::value_error(std::string(name) + ": __cuda_array_interface__ stream 0 is ambiguous (version 3 disallows it)");
    if (!c_contiguous(a.shape, strides, a.item_bytes))
        throw pyb::value_error(std::string(name) + ": expected a C-contiguous array, got strides " + shape_text(strides));
    return a;
}

#if RF_PY_DLPACK
// __dlpack__: a capsule named "dltensor" holding a DLManagedTensor, renamed
// "used_dltensor" once taken; its deleter runs when the last copy of the
// DeviceArray goes (the GIL held: the binding returns with it).
DeviceArray from_dlpack(const pyb::handle& value, const char* name, std::optional<intptr_t> stream) {
    const auto device = value.attr("__dlpack_device__")().cast<std::pair<int, int>>();
    if (device.first != kDLCUDA && device.first != kDLCUDAManaged) {
        throw pyb::value_error(std::string(name) + ": expected a CUDA device array, got DLPack device type " +
                               std::to_string(device.first) +
                               (device.first == kDLCPU ? " (the CPU: pass numpy arrays to the host batches)" : ""));
    }
    // The stream this call will run on, for the producer to order its work before (1: the legacy default stream).
    pyb::object capsule = value.attr("__dlpack__")(pyb::arg("stream") = stream ? *stream : intptr_t(1));
    auto* managed = static_cast<DLManagedTensor*>(PyCapsule_GetPointer(capsule.ptr(), "dltensor"));
    if (managed == nullptr) {
        PyErr_Clear();
        throw pyb::type_error(std::string(name) + ": __dlpack__ did not return an unused 'dltensor' capsule");
    }
    PyCapsule_SetName(capsule.ptr(), "used_dltensor");
    DeviceArray a;
    a.owner = std::shared_ptr<void>(managed, [](void* p) {
        auto* t = static_cast<DLManagedTensor*>(p);
        if (t->deleter) t->deleter(t);
    });
    const DLTensor& t = managed->dl_tensor;
    a.data = static_cast<char*>(t.data) + t.byte_offset;
    a.shape.assign(t.shape, t.shape + t.ndim);
    if (t.dtype.lanes != 1) throw pyb::type_error(std::string(name) + ": vector element types are not supported");
    a.kind = t.dtype.code == kDLFloat ? 'f' : t.dtype.code == kDLUInt ? 'u' : t.dtype.code == kDLInt ? 'i' : '?';
    a.item_bytes = t.dtype.bits / 8;
    std::vector<int64_t> strides;
    if (t.strides) {
        for (int d = 0; d < t.ndim; ++d) strides.push_back(t.strides[d] * a.item_bytes);  // DLPack counts elements
    }
    if (!c_contiguous(a.shape, strides, a.item_bytes))
        throw pyb::value_error(std::string(name) + ": expected a C-contiguous array");
    return a;
}
#endif

// ValueError unless a's shape is (rows, columns), or (rows,) for columns 0.
void check_shape(const DeviceArray& a, const char* name, int64_t rows, int64_t columns) {
    const bool shape_ok = columns == 0 ? a.shape.size() == 1 && a.shape[0] == rows
                                       : a.shape.size() == 2 && a.shape[0] == rows && a.shape[1] == columns;
    if (!shape_ok) {
        throw pyb::value_error(std::string(name) + ": expected shape " +
                               (columns == 0 ? "(" + std::to_string(rows) + ",)"
                                             : "(" + std::to_string(rows) + ", " + std::to_string(columns) + ")") +
                               ", got " + shape_text(a.shape));
    }
}

}  // namespace

DeviceArray device_array(const pyb::handle& value, const char* name, bool writable) {
    if (pyb::hasattr(value, "__cuda_array_interface__")) return from_cuda_array_interface(value, name, writable);
    if (pyb::hasattr(value, "__dlpack__") && pyb::hasattr(value, "__dlpack_device__")) {
#if RF_PY_DLPACK
        return from_dlpack(value, name, std::nullopt);
#else
        throw pyb::type_error(std::string(name) + ": this rayforge was built without DLPack (libdlpack-dev): pass an "
                              "object with __cuda_array_interface__");
#endif
    }
    throw pyb::type_error(std::string(name) + ": expected a CUDA device array (__cuda_array_interface__ or __dlpack__), got " +
                          pyb::str(pyb::type::of(value)).cast<std::string>());
}

void trace_device_arrays(const World& world, const pyb::handle& rays, const pyb::handle* hits,
                         const pyb::handle* occluded, const std::optional<intptr_t>& stream) {
    const DeviceArray r = device_array(rays, "rays", false);
    if (r.shape.size() != 2 || r.shape[1] != 8)
        throw pyb::value_error("rays: expected shape (n, 8) (ox, oy, oz, tmin, dx, dy, dz, tmax), got " +
                               shape_text(r.shape));
    if (r.kind != 'f' || r.item_bytes != 4)
        throw pyb::type_error("rays: expected float32 elements");
    const int64_t n = r.shape[0];
    DeviceArray out;
    if (hits) {
        out = device_array(*hits, "hits", true);
        check_shape(out, "hits", n, 4);
        if (out.item_bytes != 4 || (out.kind != 'f' && out.kind != 'u' && out.kind != 'i'))
            throw pyb::type_error("hits: expected 4-byte elements (float32, uint32 or int32)");
    } else {
        out = device_array(*occluded, "occluded", true);
        check_shape(out, "occluded", n, 0);
        if (out.item_bytes != 1 || (out.kind != 'u' && out.kind != 'b' && out.kind != 'i'))
            throw pyb::type_error("occluded: expected uint8 or bool elements");
    }
    if (stream && *stream < 0)
        throw pyb::value_error("stream: expected a cudaStream_t handle as a non-negative int, got " + std::to_string(*stream));
    void* s = reinterpret_cast<void*>(stream ? *stream : r.stream.value_or(0));
    pyb::gil_scoped_release release;
    if (hits) world.intersect_on_device(static_cast<const Ray*>(r.data), static_cast<Hit*>(out.data), size_t(n), s);
    else world.occluded_on_device(static_cast<const Ray*>(r.data), static_cast<uint8_t*>(out.data), size_t(n), s);
}

void bind_device_buffer(pyb::module_& m) {
#if RAYFORGE_PY_CUDA
    // Device memory of cuda:0 with a shape and a numpy dtype, its contents
    // copied in and out with numpy: what the tests and examples hand to the
    // device batches in place of a CuPy or PyTorch array.
    struct DeviceBuffer {
        std::shared_ptr<cuda::self_test::DeviceBytes> bytes;
        std::vector<int64_t> shape;
        pyb::dtype dtype;
        size_t nbytes = 0;
    };
    pyb::class_<DeviceBuffer>(m, "_DeviceBuffer",
                              "CUDA memory for tests: _DeviceBuffer(numpy_array) copies it to cuda:0; numpy() copies back.")
        .def(pyb::init([](const pyb::array& host) {
                 const pyb::array c = pyb::array::ensure(host, pyb::array::c_style);
                 DeviceBuffer b;
                 b.nbytes = size_t(c.nbytes());
                 b.bytes = std::make_shared<cuda::self_test::DeviceBytes>(b.nbytes > 0 ? b.nbytes : 1, 0);
                 b.shape.assign(c.shape(), c.shape() + c.ndim());
                 b.dtype = c.dtype();
                 b.bytes->upload(c.data(), b.nbytes);
                 return b;
             }),
             pyb::arg("host"))
        .def("numpy",
             [](const DeviceBuffer& b) {
                 pyb::array out(b.dtype, std::vector<pyb::ssize_t>(b.shape.begin(), b.shape.end()));
                 b.bytes->download(out.mutable_data(), b.nbytes);
                 return out;
             })
#if RF_PY_DLPACK
        .def("__dlpack_device__", [](const DeviceBuffer&) { return pyb::make_tuple(int(kDLCUDA), 0); })
        .def(
            "__dlpack__",
            [](const DeviceBuffer& b, const pyb::object& /*stream: written by cudaMemcpy, already complete*/) {
                // The tensor keeps the device memory alive through a shared_ptr copy.
                struct Export {
                    DLManagedTensor managed{};
                    std::vector<int64_t> shape;
                    std::shared_ptr<cuda::self_test::DeviceBytes> bytes;
                };
                auto* e = new Export{{}, b.shape, b.bytes};
                const char kind = b.dtype.kind();
                e->managed.dl_tensor.data = b.bytes->data();
                e->managed.dl_tensor.device = {kDLCUDA, 0};
                e->managed.dl_tensor.ndim = int(e->shape.size());
                e->managed.dl_tensor.dtype = {uint8_t(kind == 'f' ? kDLFloat : kind == 'i' ? kDLInt : kDLUInt),
                                              uint8_t(8 * b.dtype.itemsize()), 1};
                e->managed.dl_tensor.shape = e->shape.data();
                e->managed.manager_ctx = e;
                e->managed.deleter = [](DLManagedTensor* t) { delete static_cast<Export*>(t->manager_ctx); };
                return pyb::capsule(&e->managed, "dltensor", [](PyObject* capsule) {
                    // Never consumed: the capsule still owns the tensor.
                    if (PyCapsule_IsValid(capsule, "dltensor")) {
                        auto* t = static_cast<DLManagedTensor*>(PyCapsule_GetPointer(capsule, "dltensor"));
                        t->deleter(t);
                    }
                });
            },
            pyb::kw_only(), pyb::arg("stream") = pyb::none())
#endif
        .def_property_readonly("__cuda_array_interface__", [](const DeviceBuffer& b) {
            pyb::dict d;
            d["shape"] = pyb::tuple(pyb::cast(b.shape));
            d["typestr"] = pyb::str(b.dtype.attr("str"));
            d["data"] = pyb::make_tuple(reinterpret_cast<uintptr_t>(b.bytes->data()), false);
            d["strides"] = pyb::none();
            d["version"] = 3;
            d["stream"] = 1;  // written on the legacy default stream (cudaMemcpy)
            return d;
        });
#else
    (void)m;
#endif
}

}  // namespace rf::py
