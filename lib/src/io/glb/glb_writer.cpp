// Writing .glb files with KHR_gaussian_splatting (avsplat/io/glb.h).
#include "avsplat/io/glb.h"

#include "avsplat/core/sh.h"
#include "avsplat/io/atomic_file.h"
#include "io/glb/glb_format.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <vector>

namespace avsplat {

namespace {

using nlohmann::json;
using namespace io::glb;

constexpr std::size_t align4(std::size_t n) { return (n + 3) & ~std::size_t(3); }

void put32(std::vector<std::uint8_t>& out, std::uint32_t v) {
    const std::size_t at = out.size();
    out.resize(at + 4);
    std::memcpy(&out[at], &v, 4);
}

// One attribute: its name, accessor description and bytes.
struct Segment {
    std::string name;
    int component_type = kFloat;
    const char* type = "VEC3";
    bool normalized = false;
    std::vector<std::uint8_t> bytes;
};

template <typename T>
std::vector<std::uint8_t> as_bytes(const std::vector<T>& v) {
    std::vector<std::uint8_t> b(v.size() * sizeof(T));
    if (!v.empty()) std::memcpy(b.data(), v.data(), b.size());
    return b;
}

std::uint8_t unit_byte(double v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v * 255.0), 0L, 255L));
}

}  // namespace

void write_glb(const std::string& path, const GaussianCloud& c, const GlbOptions& options) {
    validate(c);
    const std::size_t n = c.size();
    const int k = c.sh_coeffs();
    std::vector<Segment> segs;

    std::vector<float> positions(c.means.size());
    for (std::size_t i = 0; i < positions.size(); ++i) positions[i] = kPositionSign[i % 3] * c.means[i];
    segs.push_back({"POSITION", kFloat, "VEC3", false, as_bytes(positions)});
    {
        std::vector<std::uint8_t> rgba(4 * n);
        for (std::size_t i = 0; i < n; ++i) {
            for (int ch = 0; ch < 3; ++ch) rgba[4 * i + ch] = unit_byte(sh::dc_to_color(double(c.sh[i * k * 3 + ch])));
            rgba[4 * i + 3] = unit_byte(c.opacities[i]);
        }
        segs.push_back({"COLOR_0", kUnsignedByte, "VEC4", true, std::move(rgba)});
    }
    {
        std::vector<float> xyzw(4 * n);
        for (std::size_t i = 0; i < n; ++i) {
            for (int a = 0; a < 3; ++a) xyzw[4 * i + a] = kQuaternionSign[1 + a] * c.rotations[4 * i + 1 + a];
            xyzw[4 * i + 3] = c.rotations[4 * i];
        }
        segs.push_back({kRotation, kFloat, "VEC4", false, as_bytes(xyzw)});
    }
    if (options.log_scales) {
        std::vector<float> logs(c.scales.size());
        for (std::size_t i = 0; i < logs.size(); ++i) logs[i] = std::log(c.scales[i]);
        segs.push_back({kScale, kFloat, "VEC3", false, as_bytes(logs)});
    } else {
        segs.push_back({kScale, kFloat, "VEC3", false, as_bytes(c.scales)});
    }
    segs.push_back({kOpacity, kFloat, "SCALAR", false, as_bytes(c.opacities)});
    for (int l = 0; l <= c.sh_degree; ++l)
        for (int m = 0; m <= 2 * l; ++m) {
            const int j = l * l + m;
            std::vector<float> rgb(3 * n);
            for (std::size_t i = 0; i < n; ++i)
                for (int ch = 0; ch < 3; ++ch) rgb[3 * i + ch] = kShSign[j] * c.sh[(i * k + j) * 3 + ch];
            segs.push_back({sh_attribute(l, m), kFloat, "VEC3", false, as_bytes(rgb)});
        }

    std::size_t bin_size = 0;
    for (const auto& s : segs) bin_size += align4(s.bytes.size());
    // GLB lengths are uint32; leave room for the JSON chunk.
    if (bin_size > std::numeric_limits<std::uint32_t>::max() - (std::size_t(1) << 20))
        throw std::invalid_argument("GaussianCloud: " + std::to_string(n) + " Gaussians need " + std::to_string(bin_size) +
                                    " bytes, more than a GLB file's 4 GiB");

    json views = json::array(), accessors = json::array(), attributes = json::object();
    std::size_t offset = 0;
    for (std::size_t s = 0; s < segs.size(); ++s) {
        json view = json::object();
        view["buffer"] = 0;
        view["byteOffset"] = offset;
        view["byteLength"] = segs[s].bytes.size();
        view["target"] = 34962;  // ARRAY_BUFFER
        views.push_back(view);
        json acc = json::object();
        acc["bufferView"] = s;
        acc["byteOffset"] = 0;
        acc["componentType"] = segs[s].component_type;
        acc["count"] = n;
        acc["type"] = segs[s].type;
        if (segs[s].normalized) acc["normalized"] = true;
        if (s == 0 && n > 0) {  // POSITION's bounds are required by glTF
            json lo = json::array(), hi = json::array();
            for (int a = 0; a < 3; ++a) {
                float mn = std::numeric_limits<float>::infinity(), mx = -mn;
                for (std::size_t i = 0; i < n; ++i)
                    mn = std::min(mn, positions[3 * i + a]), mx = std::max(mx, positions[3 * i + a]);
                lo.push_back(mn);
                hi.push_back(mx);
            }
            acc["min"] = lo;
            acc["max"] = hi;
        }
        accessors.push_back(acc);
        attributes[segs[s].name] = s;
        offset += align4(segs[s].bytes.size());
    }
    // Built member by member: nested brace lists are ambiguous between JSON arrays and objects.
    json ext = json::object();
    ext["kernel"] = "ellipse";
    ext["colorSpace"] = "srgb_rec709_display";
    ext["sortingMethod"] = "cameraDistance";
    ext["projection"] = "perspective";
    json primitive = json::object();
    primitive["attributes"] = attributes;
    primitive["mode"] = kModePoints;
    primitive["extensions"] = json::object();
    primitive["extensions"][kExtension] = ext;
    json mesh = json::object();
    mesh["primitives"] = json::array({primitive});
    json scene = json::object();
    scene["nodes"] = json::array({0});
    json node = json::object();
    node["mesh"] = 0;
    json buffer = json::object();
    buffer["byteLength"] = bin_size;
    json gltf = json::object();
    gltf["asset"] = json::object();
    gltf["asset"]["version"] = "2.0";
    gltf["asset"]["generator"] = "avsplat";
    gltf["extensionsUsed"] = json::array({kExtension});
    gltf["scene"] = 0;
    gltf["scenes"] = json::array({scene});
    gltf["nodes"] = json::array({node});
    gltf["buffers"] = json::array({buffer});
    gltf["bufferViews"] = views;
    gltf["accessors"] = accessors;
    gltf["meshes"] = json::array({mesh});
    std::string text = gltf.dump();
    text.resize(align4(text.size()), ' ');  // JSON chunk padded with spaces

    std::vector<std::uint8_t> head;
    put32(head, kMagic);
    put32(head, kVersion);
    put32(head, static_cast<std::uint32_t>(kHeaderSize + 2 * kChunkHeaderSize + text.size() + bin_size));
    put32(head, static_cast<std::uint32_t>(text.size()));
    put32(head, kChunkJson);
    AtomicFile out(path);
    out.write(head.data(), head.size());
    out.write(text.data(), text.size());
    head.clear();
    put32(head, static_cast<std::uint32_t>(bin_size));
    put32(head, kChunkBin);
    out.write(head.data(), head.size());
    const std::uint8_t zeros[4] = {0, 0, 0, 0};
    for (const auto& s : segs) {
        out.write(s.bytes.data(), s.bytes.size());
        out.write(zeros, align4(s.bytes.size()) - s.bytes.size());
    }
    out.commit();
}

}  // namespace avsplat
