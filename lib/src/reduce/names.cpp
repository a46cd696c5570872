#include "avsplat/reduce/names.h"

namespace avsplat {

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
