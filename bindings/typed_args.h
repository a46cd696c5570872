// Python objects that a binding converts itself, named by the type they stand for, so that
// signatures in help(), the .pyi stubs and the API reference say "numpy.typing.ArrayLike" or
// "os.PathLike" instead of pybind11's "handle" / "object". Each is a py::object (any value is
// accepted by the caster; the function body converts and checks it, raising as before); as a
// return type it names what the function returns.
#pragma once

#include <pybind11/pybind11.h>

namespace avsplat::python::typed {

inline int any_object(PyObject*) { return 1; }

}  // namespace avsplat::python::typed

// AVSPLAT_TYPED_ARG(Name, "python type"): avsplat::python::Name, a py::object whose signature
// name is the given text.
#define AVSPLAT_TYPED_ARG(Name, Text)                                                             \
    namespace avsplat::python {                                                                   \
    class Name : public pybind11::object {                                                        \
        PYBIND11_OBJECT_DEFAULT(Name, object, typed::any_object)                                  \
    };                                                                                            \
    }                                                                                             \
    namespace pybind11::detail {                                                                  \
    template <>                                                                                   \
    struct handle_type_name<avsplat::python::Name> {                                              \
        static constexpr auto name = const_name(Text);                                            \
    };                                                                                            \
    }

/// An array or anything numpy.asarray accepts.
AVSPLAT_TYPED_ARG(ArrayLike, "numpy.typing.ArrayLike")
/// An array-like or None.
AVSPLAT_TYPED_ARG(OptionalArrayLike, "typing.Optional[numpy.typing.ArrayLike]")
/// A file-system path: str, bytes or os.PathLike, as open() accepts it (paths.h).
AVSPLAT_TYPED_ARG(PathLike, "typing.Union[str, bytes, os.PathLike]")
/// A path or None.
AVSPLAT_TYPED_ARG(OptionalPathLike, "typing.Union[str, bytes, os.PathLike, None]")
/// A word from a names table (policy="occupancy"); a non-string raises TypeError.
AVSPLAT_TYPED_ARG(Word, "str")
/// An integer or None (a budget, a memory limit).
AVSPLAT_TYPED_ARG(OptionalInt, "typing.Optional[int]")
/// A sequence of cameras, or None.
AVSPLAT_TYPED_ARG(OptionalCameras, "typing.Optional[typing.Sequence[Camera]]")
/// Three floats (an RGB colour).
AVSPLAT_TYPED_ARG(Float3, "typing.Sequence[float]")
/// Any Python value (an exception's traceback, a callback's result).
AVSPLAT_TYPED_ARG(AnyValue, "typing.Any")
/// A callable or None.
AVSPLAT_TYPED_ARG(OptionalCallable, "typing.Optional[typing.Callable]")
/// A float or None.
AVSPLAT_TYPED_ARG(OptionalFloat, "typing.Optional[float]")
/// What indexes a sequence numpy's way: an int, a slice, a boolean mask or an integer array.
AVSPLAT_TYPED_ARG(IndexKey, "typing.Union[int, slice, numpy.typing.ArrayLike]")
/// What FusionStream.finish returns: the result type of the operator the stream runs.
AVSPLAT_TYPED_ARG(FusionResult, "typing.Union[FeatureFusionResult, GaussianFusionResult]")
