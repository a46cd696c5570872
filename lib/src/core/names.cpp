#include "avsplat/core/names.h"

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
const std::vector<std::pair<std::string, ConfidenceMapping>>& enum_names<ConfidenceMapping>() {
    static const std::vector<std::pair<std::string, ConfidenceMapping>> t = {
        {"logit", ConfidenceMapping::Logit},
        {"probability", ConfidenceMapping::Probability},
        {"positive", ConfidenceMapping::Positive}};
    return t;
}

template <>
const std::vector<std::pair<std::string, ShapeMode>>& enum_names<ShapeMode>() {
    static const std::vector<std::pair<std::string, ShapeMode>> t = {{"average", ShapeMode::Average},
                                                                     {"moment", ShapeMode::Moment}};
    return t;
}

template <>
const std::vector<std::pair<std::string, InvalidPolicy>>& enum_names<InvalidPolicy>() {
    static const std::vector<std::pair<std::string, InvalidPolicy>> t = {{"raise", InvalidPolicy::Raise},
                                                                         {"drop", InvalidPolicy::Drop}};
    return t;
}

template <>
const std::vector<std::pair<std::string, Precision>>& enum_names<Precision>() {
    static const std::vector<std::pair<std::string, Precision>> t = {{"float32", Precision::Float32},
                                                                     {"float64", Precision::Float64}};
    return t;
}

template <>
const std::vector<std::pair<std::string, Backend>>& enum_names<Backend>() {
    static const std::vector<std::pair<std::string, Backend>> t = {{"cpu", Backend::Cpu}, {"cuda", Backend::Cuda}};
    return t;
}

FusionPolicy parse_fusion_policy(const std::string& w, const std::string& f) { return parse_enum<FusionPolicy>(w, f); }
WeightFunction parse_weight_function(const std::string& w, const std::string& f) {
    return parse_enum<WeightFunction>(w, f);
}
ConfidenceMapping parse_confidence_mapping(const std::string& w, const std::string& f) {
    return parse_enum<ConfidenceMapping>(w, f);
}
ShapeMode parse_shape_mode(const std::string& w, const std::string& f) { return parse_enum<ShapeMode>(w, f); }
InvalidPolicy parse_invalid_policy(const std::string& w, const std::string& f) {
    return parse_enum<InvalidPolicy>(w, f);
}
Precision parse_precision(const std::string& w, const std::string& f) { return parse_enum<Precision>(w, f); }
Backend parse_backend(const std::string& w, const std::string& f) { return parse_enum<Backend>(w, f); }

template <>
const std::vector<std::pair<std::string, SpzCoordinateSystem>>& enum_names<SpzCoordinateSystem>() {
    using S = SpzCoordinateSystem;
    static const std::vector<std::pair<std::string, S>> t = {{"ldb", S::LDB}, {"rdb", S::RDB}, {"lub", S::LUB},
                                                             {"rub", S::RUB}, {"ldf", S::LDF}, {"rdf", S::RDF},
                                                             {"luf", S::LUF}, {"ruf", S::RUF}};
    return t;
}
SpzCoordinateSystem parse_spz_coordinate_system(const std::string& w, const std::string& f) {
    return parse_enum<SpzCoordinateSystem>(w, f);
}

template <>
const std::vector<std::pair<std::string, GaussianFormat>>& enum_names<GaussianFormat>() {
    static const std::vector<std::pair<std::string, GaussianFormat>> t = {
        {"ply", GaussianFormat::Ply}, {"compressed_ply", GaussianFormat::CompressedPly}, {"splat", GaussianFormat::Splat},
        {"spz", GaussianFormat::Spz}, {"sog", GaussianFormat::Sog}};
    return t;
}

template <>
const std::vector<std::pair<std::string, SimplifyMethod>>& enum_names<SimplifyMethod>() {
    static const std::vector<std::pair<std::string, SimplifyMethod>> t = {{"merge", SimplifyMethod::Merge},
                                                                          {"voxel", SimplifyMethod::Voxel}};
    return t;
}
SimplifyMethod parse_simplify_method(const std::string& w, const std::string& f) {
    return parse_enum<SimplifyMethod>(w, f);
}

}  // namespace avsplat
