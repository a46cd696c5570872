// The words of the I/O module's enums (GaussianFormat, SpzCoordinateSystem); the lookup is
// core/names.h's.
#pragma once

#include "avsplat/core/names.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/spz.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, GaussianFormat>>& enum_names<GaussianFormat>();
template <>
const std::vector<std::pair<std::string, SpzCoordinateSystem>>& enum_names<SpzCoordinateSystem>();

inline std::string to_string(GaussianFormat v) { return name_of(v); }

SpzCoordinateSystem parse_spz_coordinate_system(const std::string& word,
                                                const std::string& field = "coordinate_system");

}  // namespace avsplat
