#include "avsplat/fusion/names.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, FusionPolicy>>& enum_names<FusionPolicy>() {
    static const std::vector<std::pair<std::string, FusionPolicy>> t = {
        {"mean", FusionPolicy::Mean}, {"softmax", FusionPolicy::Softmax}, {"occupancy", FusionPolicy::Occupancy}};
    return t;
}

template <>
const std::vector<std::pair<std::string, WeightFunction>>& enum_names<WeightFunction>() {
    static const std::vector<std::pair<std::string, WeightFunction>> t = {{"softmax", WeightFunction::Softmax},
                                                                          {"sparsemax", WeightFunction::Sparsemax}};
    return t;
}

template <>
const std::vector<std::pair<std::string, ShapeMode>>& enum_names<ShapeMode>() {
    static const std::vector<std::pair<std::string, ShapeMode>> t = {{"average", ShapeMode::Average},
                                                                     {"moment", ShapeMode::Moment}};
    return t;
}

FusionPolicy parse_fusion_policy(const std::string& w, const std::string& f) { return parse_enum<FusionPolicy>(w, f); }
WeightFunction parse_weight_function(const std::string& w, const std::string& f) {
    return parse_enum<WeightFunction>(w, f);
}
ShapeMode parse_shape_mode(const std::string& w, const std::string& f) { return parse_enum<ShapeMode>(w, f); }

}  // namespace avsplat
