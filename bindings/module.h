// One registration function per binding file; module.cpp calls them in order.
#pragma once

#include <pybind11/pybind11.h>

namespace avsplat::python {

void bind_gaussians(pybind11::module_& m);
void bind_camera(pybind11::module_& m);
void bind_io(pybind11::module_& m);
void bind_point_maps(pybind11::module_& m);
void bind_render(pybind11::module_& m);
void bind_fusion(pybind11::module_& m);
void bind_stream(pybind11::module_& m);
void bind_simulator(pybind11::module_& m);
void bind_view_coverage(pybind11::module_& m);
void bind_reduce(pybind11::module_& m);
void bind_sog(pybind11::module_& m);
void bind_transform(pybind11::module_& m);
void bind_simplify(pybind11::module_& m);
void bind_lod(pybind11::module_& m);
void bind_assist(pybind11::module_& m);
void bind_predictions(pybind11::module_& m);
void bind_view(pybind11::module_& m);
void bind_registration(pybind11::module_& m);

}  // namespace avsplat::python
