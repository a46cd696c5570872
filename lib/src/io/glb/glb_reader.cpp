// Reading .glb files with KHR_gaussian_splatting (avsplat/io/glb.h).
#include "avsplat/io/glb.h"

#include "avsplat/core/error.h"
#include "avsplat/core/sh.h"
#include "io/glb/glb_format.h"
#include "io/input_file.h"

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <vector>

namespace avsplat {

namespace {

using nlohmann::json;
using namespace io::glb;

[[noreturn]] void fail(const std::string& name, const std::string& what) { throw IOError(name + ": " + what); }

std::uint32_t le32(const std::uint8_t* p) {
    std::uint32_t v;
    std::memcpy(&v, p, 4);
    return v;
}

// A non-negative integer member of a JSON object, or `fallback` when absent.
std::uint64_t uint_member(const json& obj, const char* key, const std::string& where, const std::string& name,
                          std::uint64_t fallback, bool required = false) {
    const auto it = obj.find(key);
    if (it == obj.end()) {
        if (required) fail(name, where + "." + key + ": missing");
        return fallback;
    }
    if (!it->is_number_unsigned()) fail(name, where + "." + key + ": not a non-negative integer");
    return it->get<std::uint64_t>();
}

int components(const std::string& type) {
    if (type == "SCALAR") return 1;
    if (type == "VEC2") return 2;
    if (type == "VEC3") return 3;
    if (type == "VEC4") return 4;
    return 0;
}

int component_size(int component_type) {
    switch (component_type) {
    case kByte:
    case kUnsignedByte: return 1;
    case kShort:
    case kUnsignedShort: return 2;
    case kFloat: return 4;
    default: return 0;
    }
}

// One accessor resolved to bytes of the binary chunk: element i, component c is at
// data + i * stride + c * component size. Every element lies inside the chunk.
struct View {
    const std::uint8_t* data = nullptr;
    std::size_t count = 0;
    std::size_t stride = 0;
    int components = 0;
    int component_type = kFloat;
    bool normalized = false;
    std::string attribute;  // for messages: "KHR_gaussian_splatting:SCALE"

    double get(std::size_t i, int c) const {
        const std::uint8_t* p = data + i * stride + std::size_t(c) * std::size_t(component_size(component_type));
        switch (component_type) {
        case kFloat: {
            float f;
            std::memcpy(&f, p, 4);
            return f;
        }
        case kUnsignedByte: return normalized ? p[0] / 255.0 : p[0];
        case kByte: {
            const auto v = static_cast<std::int8_t>(p[0]);
            return normalized ? std::max(v / 127.0, -1.0) : v;
        }
        case kUnsignedShort: {
            std::uint16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? v / 65535.0 : v;
        }
        case kShort: {
            std::int16_t v;
            std::memcpy(&v, p, 2);
            return normalized ? std::max(v / 32767.0, -1.0) : v;
        }
        default: return 0;
        }
    }
};

struct Document {
    std::string name;
    json gltf;
    const std::uint8_t* bin = nullptr;
    std::size_t bin_size = 0;
    bool has_bin = false;
};

Document split_chunks(const std::uint8_t* data, std::size_t size, const std::string& name) {
    if (size < kHeaderSize) fail(name, "header: the file is shorter than the 12-byte GLB header");
    if (le32(data) != kMagic) fail(name, "magic: not a GLB file (it does not start with \"glTF\")");
    const std::uint32_t version = le32(data + 4);
    if (version != kVersion) fail(name, "version: " + std::to_string(version) + " is not supported (2 is)");
    const std::uint32_t length = le32(data + 8);
    if (length > size)
        fail(name, "length: the header claims " + std::to_string(length) + " bytes, the file holds " + std::to_string(size));
    if (length < kHeaderSize) fail(name, "length: " + std::to_string(length) + " is shorter than the header");
    Document d;
    d.name = name;
    std::size_t at = kHeaderSize;
    bool has_json = false;
    for (int chunk = 0; at < length; ++chunk) {
        const std::string where = "chunks[" + std::to_string(chunk) + "]";
        if (length - at < kChunkHeaderSize) fail(name, where + ": truncated chunk header");
        const std::uint32_t chunk_length = le32(data + at), type = le32(data + at + 4);
        at += kChunkHeaderSize;
        if (chunk_length > length - at)
            fail(name, where + ".chunkLength: " + std::to_string(chunk_length) + " bytes run past the end of the file");
        const std::uint8_t* body = data + at;
        at += chunk_length;
        if (chunk == 0) {
            if (type != kChunkJson) fail(name, where + ".chunkType: the first chunk is not JSON");
            try {
                d.gltf = json::parse(body, body + chunk_length);
            } catch (const json::exception& e) {
                fail(name, where + ": invalid JSON: " + e.what());
            }
            if (!d.gltf.is_object()) fail(name, where + ": the JSON is not an object");
            has_json = true;
        } else if (chunk == 1 && type == kChunkBin) {
            d.bin = body;
            d.bin_size = chunk_length;
            d.has_bin = true;
        }
        // Other chunks are to be ignored (glTF 2.0, GLB file format).
    }
    if (!has_json) fail(name, "chunks: the file has no JSON chunk");
    return d;
}

const json& array_item(const Document& d, const char* array, std::uint64_t index, const std::string& referrer) {
    const auto it = d.gltf.find(array);
    if (it == d.gltf.end() || !it->is_array() || index >= it->size())
        fail(d.name, referrer + ": " + array + "[" + std::to_string(index) + "] does not exist");
    const json& item = (*it)[static_cast<std::size_t>(index)];
    if (!item.is_object()) fail(d.name, std::string(array) + "[" + std::to_string(index) + "]: not an object");
    return item;
}

View resolve(const Document& d, const json& attributes, const std::string& attribute) {
    const std::string where_attr = "attributes[\"" + attribute + "\"]";
    const json& ref = attributes.at(attribute);
    if (!ref.is_number_unsigned()) fail(d.name, where_attr + ": not an accessor index");
    const std::uint64_t ai = ref.get<std::uint64_t>();
    const json& acc = array_item(d, "accessors", ai, where_attr);
    const std::string where = "accessors[" + std::to_string(ai) + "]";
    if (acc.contains("sparse")) fail(d.name, where + ".sparse: sparse accessors are not supported");
    View v;
    v.attribute = attribute;
    const auto type = acc.find("type");
    if (type == acc.end() || !type->is_string() || components(type->get<std::string>()) == 0)
        fail(d.name, where + ".type: missing or not SCALAR/VEC2/VEC3/VEC4");
    v.components = components(type->get<std::string>());
    v.component_type = static_cast<int>(uint_member(acc, "componentType", where, d.name, 0, true));
    const int csize = component_size(v.component_type);
    if (csize == 0) fail(d.name, where + ".componentType: " + std::to_string(v.component_type) + " is not supported");
    const auto norm = acc.find("normalized");
    v.normalized = norm != acc.end() && norm->is_boolean() && norm->get<bool>();
    const std::uint64_t count = uint_member(acc, "count", where, d.name, 0, true);
    const std::uint64_t acc_offset = uint_member(acc, "byteOffset", where, d.name, 0);
    const std::size_t element = std::size_t(csize) * std::size_t(v.components);
    if (!acc.contains("bufferView")) fail(d.name, where + ".bufferView: missing (accessors without data are not supported)");
    const std::uint64_t bvi = uint_member(acc, "bufferView", where, d.name, 0, true);
    const json& bv = array_item(d, "bufferViews", bvi, where + ".bufferView");
    const std::string bv_where = "bufferViews[" + std::to_string(bvi) + "]";
    const std::uint64_t buffer = uint_member(bv, "buffer", bv_where, d.name, 0, true);
    const json& buf = array_item(d, "buffers", buffer, bv_where + ".buffer");
    if (buffer != 0 || buf.contains("uri"))
        fail(d.name, "buffers[" + std::to_string(buffer) + "]: only the GLB's own binary chunk is read, not external buffers");
    if (!d.has_bin) fail(d.name, "chunks[1]: the file has no binary chunk for " + bv_where);
    const std::uint64_t bv_offset = uint_member(bv, "byteOffset", bv_where, d.name, 0);
    const std::uint64_t bv_length = uint_member(bv, "byteLength", bv_where, d.name, 0, true);
    if (bv_offset > d.bin_size || bv_length > d.bin_size - bv_offset)
        fail(d.name, bv_where + ": bytes " + std::to_string(bv_offset) + " + " + std::to_string(bv_length) +
                         " run past the binary chunk of " + std::to_string(d.bin_size) + " bytes");
    const std::uint64_t stride = uint_member(bv, "byteStride", bv_where, d.name, element);
    if (stride < element || stride > 252)
        fail(d.name, bv_where + ".byteStride: " + std::to_string(stride) + " is not in " + std::to_string(element) + "..252");
    // The last element ends inside the view: offset + stride * (count - 1) + element <= length.
    if (count > 0) {
        if (acc_offset > bv_length || (count - 1) > (bv_length - acc_offset) / stride ||
            acc_offset + stride * (count - 1) + element > bv_length)
            fail(d.name, where + ".count: " + std::to_string(count) + " elements of " + std::to_string(element) +
                             " bytes at offset " + std::to_string(acc_offset) + " run past " + bv_where + " (" +
                             std::to_string(bv_length) + " bytes)");
    }
    v.data = d.bin + bv_offset + acc_offset;
    v.count = static_cast<std::size_t>(count);
    v.stride = static_cast<std::size_t>(stride);
    return v;
}

// The attribute's accessor must have `want` components of one of the allowed types.
void expect(const Document& d, const View& v, int want, std::initializer_list<int> types, bool must_normalize_ints) {
    if (v.components != want)
        fail(d.name, v.attribute + ": " + std::to_string(v.components) + " components, expected " + std::to_string(want));
    bool ok = false;
    for (int t : types) ok = ok || t == v.component_type;
    if (!ok) fail(d.name, v.attribute + ": component type " + std::to_string(v.component_type) + " is not allowed here");
    if (must_normalize_ints && v.component_type != kFloat && !v.normalized)
        fail(d.name, v.attribute + ": integer components must be normalized");
}

bool is_gaussian_primitive(const json& prim) {
    if (!prim.is_object()) return false;
    const auto ext = prim.find("extensions");
    return ext != prim.end() && ext->is_object() && ext->contains(kExtension);
}

// Appends one primitive's Gaussians to `parts`.
void read_primitive(const Document& d, const json& prim, const std::string& where, const GlbOptions& options,
                    std::vector<GaussianCloud>& parts, std::uint64_t& total) {
    const auto mode = prim.find("mode");
    if (mode != prim.end() && !(mode->is_number_unsigned() && mode->get<std::uint64_t>() == kModePoints))
        fail(d.name, where + ".mode: a Gaussian primitive must be POINTS (0)");
    const auto attrs_it = prim.find("attributes");
    if (attrs_it == prim.end() || !attrs_it->is_object()) fail(d.name, where + ".attributes: missing");
    const json& attrs = *attrs_it;
    for (const char* required : {"POSITION", kRotation, kScale, kOpacity})
        if (!attrs.contains(required)) fail(d.name, where + ".attributes: " + required + " is missing");

    const View pos = resolve(d, attrs, "POSITION");
    expect(d, pos, 3, {kFloat}, false);
    const std::size_t n = pos.count;
    // Primitives could share accessors; a file may not claim more Gaussians than its binary chunk
    // stores positions for, so that what is allocated stays bounded by the file's size.
    total += n;
    if (total > d.bin_size / 12)
        fail(d.name, where + ": the Gaussian primitives hold " + std::to_string(total) +
                         " Gaussians, more than the binary chunk's " + std::to_string(d.bin_size) +
                         " bytes store positions for");
    const View rot = resolve(d, attrs, kRotation);
    expect(d, rot, 4, {kFloat, kByte, kShort}, true);
    const View scale = resolve(d, attrs, kScale);
    expect(d, scale, 3, {kFloat, kByte, kShort}, false);
    const View opacity = resolve(d, attrs, kOpacity);
    expect(d, opacity, 1, {kFloat, kUnsignedByte, kUnsignedShort}, true);

    // SH: degree l is present when any of its coefficients is; then all of it and all below.
    int degree = 0;
    for (int l = 1; l <= 3; ++l)
        for (int c = 0; c <= 2 * l; ++c)
            if (attrs.contains(sh_attribute(l, c))) degree = l;
    for (int l = 1; l <= degree; ++l)
        for (int c = 0; c <= 2 * l; ++c)
            if (!attrs.contains(sh_attribute(l, c)))
                fail(d.name, where + ".attributes: " + sh_attribute(l, c) + " is missing while SH degree " +
                                 std::to_string(degree) + " is given (degrees may not be given in part)");
    std::vector<View> sh_views;
    const bool has_dc = attrs.contains(sh_attribute(0, 0));
    if (has_dc) {
        sh_views.push_back(resolve(d, attrs, sh_attribute(0, 0)));
        expect(d, sh_views.back(), 3, {kFloat}, false);
    } else {
        if (!attrs.contains("COLOR_0"))
            fail(d.name, where + ".attributes: " + sh_attribute(0, 0) + " is missing and there is no COLOR_0 to take the colour from");
        sh_views.push_back(resolve(d, attrs, "COLOR_0"));
        const View& col = sh_views.back();
        if (col.components != 3 && col.components != 4)
            fail(d.name, "COLOR_0: " + std::to_string(col.components) + " components, expected 3 or 4");
        expect(d, col, col.components, {kFloat, kUnsignedByte, kUnsignedShort}, true);
    }
    for (int l = 1; l <= degree; ++l)
        for (int c = 0; c <= 2 * l; ++c) {
            sh_views.push_back(resolve(d, attrs, sh_attribute(l, c)));
            expect(d, sh_views.back(), 3, {kFloat}, false);
        }
    for (const View* v : {&rot, &scale, &opacity})
        if (v->count != n)
            fail(d.name, v->attribute + ": " + std::to_string(v->count) + " elements, POSITION has " + std::to_string(n));
    for (const View& v : sh_views)
        if (v.count != n) fail(d.name, v.attribute + ": " + std::to_string(v.count) + " elements, POSITION has " + std::to_string(n));

    // Every element was checked to lie in the binary chunk: n is bounded by the file's size.
    GaussianCloud c(n, degree);
    const int k = c.sh_coeffs();
    for (std::size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) c.means[3 * i + a] = kPositionSign[a] * static_cast<float>(pos.get(i, a));
        // File order x, y, z, w; avsplat's w, x, y, z.
        c.rotations[4 * i] = static_cast<float>(rot.get(i, 3));
        for (int a = 0; a < 3; ++a) c.rotations[4 * i + 1 + a] = kQuaternionSign[1 + a] * static_cast<float>(rot.get(i, a));
        for (int a = 0; a < 3; ++a) {
            const double s = scale.get(i, a);
            c.scales[3 * i + a] = static_cast<float>(options.log_scales ? std::exp(s) : s);
        }
        c.opacities[i] = static_cast<float>(opacity.get(i, 0));
        for (int j = 0; j < k; ++j)
            for (int ch = 0; ch < 3; ++ch) {
                const double v = sh_views[static_cast<std::size_t>(j)].get(i, ch);
                c.sh[(i * std::size_t(k) + std::size_t(j)) * 3 + std::size_t(ch)] =
                    kShSign[j] * static_cast<float>(j == 0 && !has_dc ? sh::color_to_dc(v) : v);
            }
    }
    parts.push_back(std::move(c));
}

}  // namespace

bool is_glb(const std::uint8_t* data, std::size_t size) { return size >= 4 && le32(data) == kMagic; }

GaussianCloud parse_glb(const std::uint8_t* data, std::size_t size, const std::string& name, const GlbOptions& options) {
    const Document d = split_chunks(data, size, name);
    // Node transforms would move the Gaussians; this reader does not apply them, so it refuses them.
    if (const auto nodes = d.gltf.find("nodes"); nodes != d.gltf.end() && nodes->is_array())
        for (std::size_t i = 0; i < nodes->size(); ++i) {
            const json& node = (*nodes)[i];
            if (!node.is_object()) continue;
            for (const char* key : {"matrix", "translation", "rotation", "scale"})
                if (node.contains(key))
                    fail(name, "nodes[" + std::to_string(i) + "]." + key + ": node transforms are not applied by this reader");
        }
    std::vector<GaussianCloud> parts;
    std::uint64_t total = 0;
    const auto meshes = d.gltf.find("meshes");
    if (meshes != d.gltf.end() && meshes->is_array())
        for (std::size_t m = 0; m < meshes->size(); ++m) {
            const json& mesh = (*meshes)[m];
            if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
            const json& prims = mesh["primitives"];
            for (std::size_t p = 0; p < prims.size(); ++p)
                if (is_gaussian_primitive(prims[p]))
                    read_primitive(d, prims[p], "meshes[" + std::to_string(m) + "].primitives[" + std::to_string(p) + "]",
                                   options, parts, total);
        }
    if (parts.empty()) fail(name, "meshes: no primitive carries the KHR_gaussian_splatting extension");
    if (parts.size() == 1) return std::move(parts.front());
    return concatenate(parts);  // SH of lower degree zero-padded to the highest
}

GaussianCloud read_glb(const std::string& path, const GlbOptions& options) {
    const std::uint64_t size = io::regular_file_size(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
    if (size && !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(size)))
        throw IOError(path + ": read failed");
    return parse_glb(bytes.data(), bytes.size(), path, options);
}

}  // namespace avsplat
