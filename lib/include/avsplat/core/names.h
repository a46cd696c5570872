// The one table of the words that name the library's enum values, as the Python API
// (policy="occupancy") and the command line (--policy occupancy) spell them. Bindings and CLI
// both read these tables, so a new value or a renamed word changes everywhere at once.
#pragma once

#include "avsplat/core/precision.h"
#include "avsplat/fusion/confidence.h"
#include "avsplat/fusion/fusion.h"
#include "avsplat/fusion/voxel_grid.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/render/render.h"
#include "avsplat/io/spz.h"
#include "avsplat/reduce/simplify.h"

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace avsplat {

/// (word, value) for every value of enum E, in declaration order. Defined for FusionPolicy,
/// WeightFunction, ConfidenceMapping, ShapeMode, InvalidPolicy, Precision, Backend and SimplifyMethod.
template <class E>
const std::vector<std::pair<std::string, E>>& enum_names();

template <>
const std::vector<std::pair<std::string, FusionPolicy>>& enum_names<FusionPolicy>();
template <>
const std::vector<std::pair<std::string, WeightFunction>>& enum_names<WeightFunction>();
template <>
const std::vector<std::pair<std::string, ConfidenceMapping>>& enum_names<ConfidenceMapping>();
template <>
const std::vector<std::pair<std::string, ShapeMode>>& enum_names<ShapeMode>();
template <>
const std::vector<std::pair<std::string, InvalidPolicy>>& enum_names<InvalidPolicy>();
template <>
const std::vector<std::pair<std::string, Precision>>& enum_names<Precision>();
template <>
const std::vector<std::pair<std::string, Backend>>& enum_names<Backend>();
template <>
const std::vector<std::pair<std::string, SpzCoordinateSystem>>& enum_names<SpzCoordinateSystem>();
template <>
const std::vector<std::pair<std::string, GaussianFormat>>& enum_names<GaussianFormat>();
template <>
const std::vector<std::pair<std::string, SimplifyMethod>>& enum_names<SimplifyMethod>();

/// The words of E joined, each quoted: "'mean', 'softmax', 'occupancy'" (for messages), or with
/// `separator` and no quotes when one is given: "mean|softmax|occupancy" (for --help).
template <class E>
std::string enum_words(const char* separator = nullptr) {
    std::string out;
    for (const auto& [word, value] : enum_names<E>()) {
        (void)value;
        if (!out.empty()) out += separator ? separator : ", ";
        out += separator ? word : "'" + word + "'";
    }
    return out;
}

/// The word of `value`. Throws std::invalid_argument for a value outside the enum.
template <class E>
const std::string& name_of(E value) {
    for (const auto& entry : enum_names<E>())
        if (entry.second == value) return entry.first;
    throw std::invalid_argument("name_of: value " + std::to_string(static_cast<long long>(value)) +
                                " is not in the names table");
}

/// The value named `word` (exact, case-sensitive). Throws std::invalid_argument
/// "<field>: '<word>' is not one of 'a', 'b', ..." naming the field and every valid word.
template <class E>
E parse_enum(const std::string& word, const std::string& field) {
    for (const auto& [name, value] : enum_names<E>())
        if (name == word) return value;
    throw std::invalid_argument(field + ": '" + word + "' is not one of " + enum_words<E>());
}

inline std::string to_string(FusionPolicy v) { return name_of(v); }
inline std::string to_string(WeightFunction v) { return name_of(v); }
inline std::string to_string(ConfidenceMapping v) { return name_of(v); }
inline std::string to_string(ShapeMode v) { return name_of(v); }
inline std::string to_string(InvalidPolicy v) { return name_of(v); }
inline std::string to_string(Precision v) { return name_of(v); }
inline std::string to_string(Backend v) { return name_of(v); }
inline std::string to_string(GaussianFormat v) { return name_of(v); }
inline std::string to_string(SimplifyMethod v) { return name_of(v); }

/// parse_<enum>(word, field): parse_enum for one enum; `field` names the argument in the error.
FusionPolicy parse_fusion_policy(const std::string& word, const std::string& field = "policy");
WeightFunction parse_weight_function(const std::string& word, const std::string& field = "weights");
ConfidenceMapping parse_confidence_mapping(const std::string& word, const std::string& field = "confidence_mapping");
ShapeMode parse_shape_mode(const std::string& word, const std::string& field = "shape");
InvalidPolicy parse_invalid_policy(const std::string& word, const std::string& field = "on_invalid");
Precision parse_precision(const std::string& word, const std::string& field = "precision");
Backend parse_backend(const std::string& word, const std::string& field = "backend");
SpzCoordinateSystem parse_spz_coordinate_system(const std::string& word,
                                                const std::string& field = "coordinate_system");
SimplifyMethod parse_simplify_method(const std::string& word, const std::string& field = "method");

}  // namespace avsplat
