// read_ply and write_ply against files and names of the other Gaussian formats.
#include "avsplat/core/error.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/spz.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

namespace {

std::string tmp(const std::string& name) { return std::string(AVSPLAT_TEST_TMP) + "/" + name; }

avsplat::GaussianCloud small_cloud() {
    avsplat::GaussianCloud c(3, 0);
    for (int i = 0; i < 9; ++i) c.means[std::size_t(i)] = 0.1f * float(i);
    for (float& s : c.scales) s = 0.05f;
    for (float& o : c.opacities) o = 0.5f;
    return c;
}

}  // namespace

TEST_CASE("write_ply refuses a name that says another format and writes nothing", "[ply]") {
    const avsplat::GaussianCloud c = small_cloud();
    for (const std::string name : {"w.sog", "w.spz", "w.splat", "w.compressed.ply", "W.SOG"}) {
        std::filesystem::remove(tmp(name));
        CHECK_THROWS_WITH(avsplat::write_ply(tmp(name), c),
                          Catch::Contains(tmp(name)) && Catch::Contains("write_gaussians"));
        CHECK_FALSE(std::filesystem::exists(tmp(name)));
    }
    // .ply and names no Gaussian format claims are PLY names.
    for (const std::string name : {"w.ply", "w.bin", "w_no_suffix"}) {
        avsplat::write_ply(tmp(name), c);
        CHECK(avsplat::read_ply(tmp(name)).size() == 3);
    }
}

TEST_CASE("read_ply names the format of a file that is not PLY", "[ply]") {
    avsplat::write_spz(tmp("r.spz"), small_cloud());
    CHECK_THROWS_WITH(avsplat::read_ply(tmp("r.spz")), Catch::Contains(tmp("r.spz")) &&
                                                           Catch::Contains("not a PLY file") &&
                                                           Catch::Contains("SPZ") && !Catch::Contains("NUL byte"));
    // A file of no known format keeps the PLY reader's own message.
    std::ofstream(tmp("r.txt")) << "hello\n";
    CHECK_THROWS_WITH(avsplat::read_ply(tmp("r.txt")), Catch::Contains("not a PLY file"));
}
