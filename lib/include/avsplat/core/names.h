// The words that name enum values, as the Python API (policy="occupancy") and the command line
// (--policy occupancy) spell them. Each module owns the words of its own enums and declares
// them in its `names.h` (core: InvalidPolicy, Precision, ConfidenceMapping; fusion, io, render,
// reduce: theirs); this header holds the lookup every table shares. Bindings and CLI read the
// tables, so a new value or a renamed word changes everywhere at once.
#pragma once

#include "avsplat/core/confidence.h"
#include "avsplat/core/invalid_policy.h"
#include "avsplat/core/precision.h"

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace avsplat {

/// (word, value) for every value of enum E, in declaration order. Specialised by the module
/// that owns E, in its names.h.
template <class E>
const std::vector<std::pair<std::string, E>>& enum_names();

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

// The core's enums.
template <>
const std::vector<std::pair<std::string, InvalidPolicy>>& enum_names<InvalidPolicy>();
template <>
const std::vector<std::pair<std::string, Precision>>& enum_names<Precision>();
template <>
const std::vector<std::pair<std::string, ConfidenceMapping>>& enum_names<ConfidenceMapping>();

inline std::string to_string(InvalidPolicy v) { return name_of(v); }
inline std::string to_string(Precision v) { return name_of(v); }
inline std::string to_string(ConfidenceMapping v) { return name_of(v); }

/// parse_<enum>(word, field): parse_enum for one enum; `field` names the argument in the error.
InvalidPolicy parse_invalid_policy(const std::string& word, const std::string& field = "on_invalid");
Precision parse_precision(const std::string& word, const std::string& field = "precision");
ConfidenceMapping parse_confidence_mapping(const std::string& word,
                                           const std::string& field = "confidence_mapping");

}  // namespace avsplat
