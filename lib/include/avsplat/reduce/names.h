// The words of the reduce module's enum (SimplifyMethod); the lookup is core/names.h's.
#pragma once

#include "avsplat/core/names.h"
#include "avsplat/reduce/simplify.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, SimplifyMethod>>& enum_names<SimplifyMethod>();

inline std::string to_string(SimplifyMethod v) { return name_of(v); }

SimplifyMethod parse_simplify_method(const std::string& word, const std::string& field = "method");

}  // namespace avsplat
