// The words of the render module's enum (Backend); the lookup is core/names.h's.
#pragma once

#include "avsplat/core/names.h"
#include "avsplat/render/render.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, Backend>>& enum_names<Backend>();

inline std::string to_string(Backend v) { return name_of(v); }

Backend parse_backend(const std::string& word, const std::string& field = "backend");

}  // namespace avsplat
