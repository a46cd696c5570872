#include "io/sog/webp_image.h"

#include "avsplat/core/error.h"
#include "core/interrupt_poll.h"

#include <webp/decode.h>
#include <webp/encode.h>

namespace avsplat::sog {

namespace {

int collect(const std::uint8_t* data, std::size_t size, const WebPPicture* picture) {
    auto* out = static_cast<std::string*>(picture->custom_ptr);
    out->append(reinterpret_cast<const char*>(data), size);
    return 1;
}

}  // namespace

std::string encode_webp(const RgbaImage& image, const std::string& what) {
    WebPConfig config;
    if (!WebPConfigInit(&config) || !WebPConfigLosslessPreset(&config, 6))
        throw IOError(what + ": libwebp configuration failed");
    config.exact = 1;  // keep RGB under alpha 0: sh0's colour indices
    WebPPicture picture;
    if (!WebPPictureInit(&picture)) throw IOError(what + ": libwebp version mismatch");
    picture.use_argb = 1;
    picture.width = image.width;
    picture.height = image.height;
    std::string out;
    picture.writer = collect;
    picture.custom_ptr = &out;
    // Large images take seconds: libwebp reports progress, and stops when the hook returns 0.
    InterruptPoll poll;
    picture.user_data = &poll;
    picture.progress_hook = [](int, const WebPPicture* p) -> int {
        return static_cast<InterruptPoll*>(p->user_data)->stop() ? 0 : 1;
    };
    struct Free {
        WebPPicture* p;
        ~Free() { WebPPictureFree(p); }
    } free_picture{&picture};
    if (!WebPPictureImportRGBA(&picture, image.rgba.data(), image.width * 4))
        throw IOError(what + ": out of memory importing a " + std::to_string(image.width) + " x " +
                      std::to_string(image.height) + " image into libwebp");
    if (!WebPEncode(&config, &picture) && poll.stopped()) throw Interrupted();
    if (picture.error_code != VP8_ENC_OK)
        throw IOError(what + ": WebP encoding failed (libwebp error " + std::to_string(picture.error_code) + ")");
    return out;
}

std::pair<int, int> webp_size(const std::string& bytes, const std::string& where) {
    int w = 0, h = 0;
    if (!WebPGetInfo(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size(), &w, &h))
        throw IOError(where + ": not a WebP image");
    if (w <= 0 || h <= 0 || w > kMaxWebpSide || h > kMaxWebpSide)
        throw IOError(where + ": WebP size " + std::to_string(w) + " x " + std::to_string(h) + " is not valid");
    return {w, h};
}

RgbaImage decode_webp(const std::string& bytes, const std::string& where, std::size_t max_pixels) {
    const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());
    const auto [w, h] = webp_size(bytes, where);
    RgbaImage img;
    img.width = w;
    img.height = h;
    if (img.pixels() > max_pixels)
        throw IOError(where + ": " + std::to_string(w) + " x " + std::to_string(h) +
                      " texels, more than the " + std::to_string(max_pixels) + " its meta.json count allows");
    img.rgba.resize(img.pixels() * 4);
    if (!WebPDecodeRGBAInto(data, bytes.size(), img.rgba.data(), img.rgba.size(), w * 4))
        throw IOError(where + ": WebP data is corrupt or truncated");
    return img;
}

}  // namespace avsplat::sog
