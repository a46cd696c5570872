#include "avsplat/io/names.h"

namespace avsplat {

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
        {"spz", GaussianFormat::Spz}, {"sog", GaussianFormat::Sog}, {"glb", GaussianFormat::Glb},
        {"ksplat", GaussianFormat::Ksplat}, {"lod_set", GaussianFormat::LodSet}};
    return t;
}

}  // namespace avsplat
