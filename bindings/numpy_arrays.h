// numpy <-> C++ array conversion shared by the binding files.
//
// The rule for inputs: any numeric dtype and any memory layout is accepted and converted once
// to C-contiguous float32 (no copy when it already is); a wrong shape raises ValueError naming
// the argument and the expected shape. Outputs are numpy arrays that view C++ storage kept
// alive by a Python owner, or own a copy.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace avsplat::python {

namespace py = pybind11;

/// A C-contiguous numpy array of T that converts any numeric input (no copy when it already is).
template <class T>
using ArrayOf = py::array_t<T, py::array::c_style | py::array::forcecast>;
using FloatArray = ArrayOf<float>;

/// `obj` as a C-contiguous array of T, any shape: the one conversion rule. Real numbers only
/// (forcecast would turn complex numbers into their real part with only a warning, and object or
/// string arrays into whatever numpy makes of them). Throws ValueError "<arg>: expected a <kind>
/// array ..." when `obj` is not such an array, and MemoryError naming `arg` when the converted
/// copy does not fit in memory (a broadcast or strided view of a huge array).
template <class T>
ArrayOf<T> as_contiguous(const py::handle& obj, const char* arg, const char* kind) {
    py::object arr = py::reinterpret_borrow<py::object>(obj);
    if (!py::isinstance<py::array>(arr)) {
        try {
            arr = py::module_::import("numpy").attr("asarray")(obj);
        } catch (const py::error_already_set&) {
            throw py::value_error(std::string(arg) + ": expected a " + kind + " array");
        }
    }
    const char dtype_kind = py::reinterpret_borrow<py::array>(arr).dtype().kind();
    if (std::string("biuf").find(dtype_kind) == std::string::npos)
        throw py::value_error(std::string(arg) + ": expected a " + kind + " array of real numbers, got dtype " +
                              py::str(py::reinterpret_borrow<py::array>(arr).dtype()).cast<std::string>());
    ArrayOf<T> a;
    try {
        a = ArrayOf<T>::ensure(arr);
    } catch (const py::error_already_set&) {
        a = ArrayOf<T>();
    }
    if (!a) {
        // ensure() swallows numpy's error: ask numpy again, so that a copy that does not fit in
        // memory is a MemoryError naming the argument, not a misleading shape error.
        try {
            py::module_::import("numpy").attr("ascontiguousarray")(arr, py::dtype::of<T>());
        } catch (py::error_already_set& e) {
            if (e.matches(PyExc_MemoryError)) {
                const std::string why = py::str(e.value());
                PyErr_SetString(PyExc_MemoryError, (std::string(arg) + ": converting to a contiguous " + kind +
                                                    " array: " + why).c_str());
                throw py::error_already_set();
            }
        }
        throw py::value_error(std::string(arg) + ": expected a " + kind + " array");
    }
    return a;
}

/// `obj` as a C-contiguous array of T with `shape`, -1 in shape meaning "any" (N); `dims` names
/// the shape in messages, e.g. "N, 3", and `kind` the element type ("float", "bool").
/// Throws ValueError "<arg>: expected a <kind> array of shape (<dims>)" when `obj` is not
/// numeric, "<arg>: expected shape (<dims>), got (...)" when the shape differs.
template <class T>
ArrayOf<T> as_array(const py::handle& obj, const char* arg, std::vector<py::ssize_t> shape,
                    const char* dims, const char* kind) {
    ArrayOf<T> a;
    try {
        a = as_contiguous<T>(obj, arg, kind);
    } catch (const py::value_error& e) {
        const std::string what = e.what();
        if (what.find("real numbers") != std::string::npos) throw;
        throw py::value_error(std::string(arg) + ": expected a " + kind + " array of shape (" + dims + ")");
    }
    bool ok = a.ndim() == static_cast<py::ssize_t>(shape.size());
    for (std::size_t k = 0; ok && k < shape.size(); ++k)
        ok = shape[k] < 0 || a.shape(k) == shape[k];
    if (!ok) {
        std::string got = "(";
        for (py::ssize_t k = 0; k < a.ndim(); ++k) got += (k ? ", " : "") + std::to_string(a.shape(k));
        got += a.ndim() == 1 ? ",)" : ")";
        throw py::value_error(std::string(arg) + ": expected shape (" + dims + "), got " + got);
    }
    return a;
}

/// as_array for float32 inputs (the common case: positions, colours, confidences).
inline FloatArray as_float_array(const py::handle& obj, const char* arg,
                                 std::vector<py::ssize_t> shape, const char* dims) {
    return as_array<float>(obj, arg, std::move(shape), dims, "float");
}

/// A numpy view of `data` with `shape`, kept alive by `owner`.
template <class T>
py::array_t<T> view(T* data, std::vector<py::ssize_t> shape, py::handle owner) {
    return py::array_t<T>(shape, data, owner);
}

/// A numpy array that owns a copy of `v` with `shape`.
template <class T>
py::array_t<T> copy_out(const std::vector<T>& v, std::vector<py::ssize_t> shape) {
    py::array_t<T> a(shape);
    std::copy(v.begin(), v.end(), a.mutable_data());
    return a;
}

/// A numpy array that takes ownership of `v` without copying.
template <class T>
py::array_t<T> move_out(std::vector<T>&& v, std::vector<py::ssize_t> shape) {
    auto* heap = new std::vector<T>(std::move(v));
    py::capsule free_when_done(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
    return py::array_t<T>(shape, heap->data(), free_when_done);
}

}  // namespace avsplat::python
