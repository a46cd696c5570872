#include "avsplat/io/ply.h"

#include "avsplat/error.h"

#include <catch2/catch.hpp>

TEST_CASE("read_ply: a missing file is an IOError", "[ply]") {
    REQUIRE_THROWS_AS(avsplat::read_ply(AVSPLAT_TEST_TMP "/does_not_exist.ply"), avsplat::IOError);
}
