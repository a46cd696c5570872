// Private: the lossless WebP images of a SOG, through Debian's libwebp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace avsplat::sog {

/// WebP's largest width and height.
constexpr int kMaxWebpSide = 16383;

struct RgbaImage {
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> rgba;  // width * height * 4, row-major
    std::size_t pixels() const { return std::size_t(width) * std::size_t(height); }
};

/// Lossless WebP of `image`, every RGB value kept exactly, transparent texels included (libwebp's
/// `exact` mode: sh0.webp stores colour indices under opacity 0). Throws IOError naming `what`
/// when libwebp fails.
std::string encode_webp(const RgbaImage& image, const std::string& what);

/// Width and height from the WebP header, without decoding. Throws IOError naming `where` when
/// `bytes` is not a WebP image or the size is not within 1..kMaxWebpSide.
std::pair<int, int> webp_size(const std::string& bytes, const std::string& where);

/// Decodes WebP `bytes` to RGBA. The header's size is checked first: a width or height above
/// kMaxWebpSide or more than `max_pixels` texels throws IOError naming `where`, before anything
/// is allocated; so does data libwebp cannot decode.
RgbaImage decode_webp(const std::string& bytes, const std::string& where, std::size_t max_pixels);

}  // namespace avsplat::sog
