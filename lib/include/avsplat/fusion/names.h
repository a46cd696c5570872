// The words of the fusion module's enums (FusionPolicy, WeightFunction, ShapeMode); the lookup
// is core/names.h's.
#pragma once

#include "avsplat/core/names.h"
#include "avsplat/fusion/confidence.h"
#include "avsplat/fusion/fusion.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, FusionPolicy>>& enum_names<FusionPolicy>();
template <>
const std::vector<std::pair<std::string, WeightFunction>>& enum_names<WeightFunction>();
template <>
const std::vector<std::pair<std::string, ShapeMode>>& enum_names<ShapeMode>();

inline std::string to_string(FusionPolicy v) { return name_of(v); }
inline std::string to_string(WeightFunction v) { return name_of(v); }
inline std::string to_string(ShapeMode v) { return name_of(v); }

FusionPolicy parse_fusion_policy(const std::string& word, const std::string& field = "policy");
WeightFunction parse_weight_function(const std::string& word, const std::string& field = "weights");
ShapeMode parse_shape_mode(const std::string& word, const std::string& field = "shape");

}  // namespace avsplat
