// FusionParams from Python keyword knobs, shared by the fusion bindings.
#pragma once

#include "avsplat/fusion/fusion.h"

#include <pybind11/pybind11.h>

#include <string>

namespace avsplat::python {

/// FusionParams from the policy name and the keyword knobs of `function` (names of the
/// FusionParams fields). Unknown knobs raise TypeError naming them; bad values ValueError naming
/// the knob; `gaussian` says whether the shape knob applies.
FusionParams parse_fusion_params(const std::string& function, const pybind11::handle& policy,
                                 const pybind11::kwargs& knobs, bool gaussian);

}  // namespace avsplat::python
