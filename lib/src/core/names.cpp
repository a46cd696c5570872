#include "avsplat/core/names.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, ConfidenceMapping>>& enum_names<ConfidenceMapping>() {
    static const std::vector<std::pair<std::string, ConfidenceMapping>> t = {
        {"logit", ConfidenceMapping::Logit},
        {"probability", ConfidenceMapping::Probability},
        {"positive", ConfidenceMapping::Positive}};
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

ConfidenceMapping parse_confidence_mapping(const std::string& w, const std::string& f) {
    return parse_enum<ConfidenceMapping>(w, f);
}
InvalidPolicy parse_invalid_policy(const std::string& w, const std::string& f) {
    return parse_enum<InvalidPolicy>(w, f);
}
Precision parse_precision(const std::string& w, const std::string& f) { return parse_enum<Precision>(w, f); }

}  // namespace avsplat
