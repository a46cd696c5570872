#include "avsplat/render/names.h"

namespace avsplat {

template <>
const std::vector<std::pair<std::string, Backend>>& enum_names<Backend>() {
    static const std::vector<std::pair<std::string, Backend>> t = {{"cpu", Backend::Cpu}, {"cuda", Backend::Cuda}};
    return t;
}
Backend parse_backend(const std::string& w, const std::string& f) { return parse_enum<Backend>(w, f); }

}  // namespace avsplat
