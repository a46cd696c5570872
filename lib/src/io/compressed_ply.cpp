// PlayCanvas compressed PLY (io/compressed_ply.h) on the PLY primitives (io/ply/ply_format.h):
// the header parser, bounded binary reads and typed loads. The quantisation mirrors
// splat-transform 3.7.0's CompressedChunk.pack and readCompressedChunked.
#include "avsplat/io/compressed_ply.h"

#include "avsplat/core/sh.h"
#include "avsplat/io/atomic_file.h"
#include "io/ply/ply_format.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace avsplat {

namespace {

using ply::fail;

constexpr std::size_t kChunk = 256;
// Bounds of a chunk, in the order the format writes them.
constexpr const char* kBoundNames[18] = {
    "min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
    "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z",
    "min_r", "min_g", "min_b", "max_r", "max_g", "max_b"};
constexpr int kGeometryBounds = 12;  // the colour bounds (last six) are optional
constexpr const char* kPackedNames[4] = {"packed_position", "packed_rotation", "packed_scale", "packed_color"};
// Scale bounds are clamped so that a zero scale (log -inf) or a huge one stays representable.
constexpr double kLogScaleLimit = 20.0;
// sqrt(2) / 2 as splat-transform computes it: the largest a non-largest unit-quaternion
// component can be.
const double kRotNorm = std::sqrt(2.0) * 0.5;
const double kInvRotNorm = 1.0 / kRotNorm;

std::size_t chunks_for(std::uint64_t n) { return static_cast<std::size_t>(n / kChunk + (n % kChunk != 0)); }

// ---------------------------------------------------------------------------------------------
// Quantisation (both directions), exactly as splat-transform.

double unpack_unorm(std::uint32_t v, int bits) {
    const std::uint32_t t = (1u << bits) - 1u;
    return double(v & t) / double(t);
}

std::uint32_t pack_unorm(double v, int bits) {
    const double t = double((1u << bits) - 1u);
    return static_cast<std::uint32_t>(std::clamp(std::floor(v * t + 0.5), 0.0, t));
}

// Largest magnitude a chunk bound may decode to (position, scale, SH DC); the reader refuses more
// and the writer refuses a cloud that would need more.
constexpr double kMaxDecoded = 1e38;

double lerp(double a, double b, double t) { return a * (1 - t) + b * t; }

double normalize(double x, double lo, double hi) {
    if (x <= lo) return 0;
    if (x >= hi) return 1;
    return hi - lo < 0.00001 ? 0 : (x - lo) / (hi - lo);
}

double decode_sh_byte(std::uint8_t b) {
    const double n = b == 0 ? 0.0 : b == 255 ? 1.0 : (b + 0.5) / 256.0;
    return (n - 0.5) * 8.0;
}

std::uint8_t encode_sh(float f) {
    const double v = (double(f) / 8.0 + 0.5) * 256.0;
    return static_cast<std::uint8_t>(std::clamp(std::trunc(v), 0.0, 255.0));
}

// ---------------------------------------------------------------------------------------------
// Reading.

struct Field {
    std::size_t offset = 0;  // bytes into the row
    PlyType type = PlyType::Float32;
};

const ply::Property* find_property(const ply::Element& e, const std::string& name, std::size_t* offset) {
    std::size_t off = 0;
    for (const auto& p : e.properties) {
        if (p.name == name) {
            *offset = off;
            return &p;
        }
        off += ply::type_size(p.type);
    }
    return nullptr;
}

struct Layout {
    const ply::Element* chunk = nullptr;
    const ply::Element* vertex = nullptr;
    const ply::Element* sh = nullptr;
    std::array<Field, 18> bounds;
    bool colour_bounds = false;
    std::array<std::size_t, 4> packed{};  // byte offsets of the packed words
    std::vector<std::size_t> rest;         // byte offset of f_rest_k in an sh row
    int degree = 0;
};

Layout plan(const ply::Header& h, const std::string& path) {
    Layout L;
    for (const auto& e : h.elements) {
        const ply::Element** slot = e.name == "chunk" ? &L.chunk : e.name == "vertex" ? &L.vertex : e.name == "sh" ? &L.sh : nullptr;
        if (!slot) continue;
        if (*slot) fail(path, "two \"" + e.name + "\" elements");
        if (e.has_lists()) fail(path, "element \"" + e.name + "\" has a list property; compressed PLY has none");
        *slot = &e;
    }
    if (!L.vertex) fail(path, "no \"vertex\" element");
    if (!L.chunk) fail(path, "no \"chunk\" element: not a compressed PLY");

    for (int k = 0; k < 4; ++k) {
        const ply::Property* p = find_property(*L.vertex, kPackedNames[k], &L.packed[k]);
        if (!p) fail(path, std::string("vertex element has no \"") + kPackedNames[k] + "\" property");
        if (p->type != PlyType::UInt32)
            fail(path, std::string("vertex property \"") + kPackedNames[k] + "\" is " + ply::type_name(p->type) +
                           "; compressed PLY packs it in a uint32");
    }
    int colour = 0;
    for (int k = 0; k < 18; ++k) {
        const ply::Property* p = find_property(*L.chunk, kBoundNames[k], &L.bounds[k].offset);
        if (p) L.bounds[k].type = p->type;
        if (k < kGeometryBounds && !p) fail(path, std::string("chunk element has no \"") + kBoundNames[k] + "\" property");
        if (k >= kGeometryBounds && p) ++colour;
    }
    if (colour != 0 && colour != 6)
        fail(path, "chunk element has " + std::to_string(colour) + " of the 6 colour bounds min_r .. max_b (all or none)");
    L.colour_bounds = colour == 6;

    const std::uint64_t n = L.vertex->count;
    if (L.chunk->count != chunks_for(n))
        fail(path, "chunk element has " + std::to_string(L.chunk->count) + " rows; " + std::to_string(n) +
                       " vertices need ceil(" + std::to_string(n) + " / 256) = " + std::to_string(chunks_for(n)));
    if (L.sh) {
        const std::size_t R = L.sh->properties.size();
        for (int d = 1; d <= kMaxShDegree; ++d)
            if (R == 3u * static_cast<std::size_t>(sh_coeffs_for_degree(d) - 1)) L.degree = d;
        if (L.degree == 0)
            fail(path, "sh element has " + std::to_string(R) + " properties; compressed PLY has 9, 24 or 45 (SH degree 1..3)");
        if (L.sh->count != n)
            fail(path, "sh element has " + std::to_string(L.sh->count) + " rows for " + std::to_string(n) + " vertices");
        L.rest.resize(R);
        for (std::size_t k = 0; k < R; ++k) {
            const std::string name = "f_rest_" + std::to_string(k);
            const ply::Property* p = find_property(*L.sh, name, &L.rest[k]);
            if (!p) fail(path, "sh element has no \"" + name + "\" property (expected f_rest_0 .. f_rest_" + std::to_string(R - 1) + ")");
            if (p->type != PlyType::UInt8)
                fail(path, "sh property \"" + name + "\" is " + ply::type_name(p->type) + "; compressed PLY stores uchar");
        }
    }
    return L;
}

GaussianCloud read_stream(std::istream& in, std::uint64_t size, const std::string& path) {
    if (size == 0) fail(path, "empty file (not a PLY file)");
    const ply::Header h = ply::read_header(in, path);
    if (h.format == PlyFormat::Ascii) fail(path, "an ASCII PLY cannot be a compressed PLY (it is binary)");
    const Layout L = plan(h, path);
    const bool swap = (h.format == PlyFormat::BinaryBigEndian) == ply::kHostLittleEndian;

    // The three elements' rows, read whole (their size is checked against the bytes left first,
    // so nothing here is larger than the file); other elements are skipped.
    ply::BinaryReader r(in, size - h.data_offset, path);
    std::vector<unsigned char> chunk_rows, vertex_rows, sh_rows;
    for (const auto& e : h.elements) {
        std::vector<unsigned char>* dst = &e == L.chunk ? &chunk_rows : &e == L.vertex ? &vertex_rows : &e == L.sh ? &sh_rows : nullptr;
        if (!dst) {
            ply::skip_binary_element(r, e, swap);
            continue;
        }
        const std::size_t row = e.row_size();
        const std::string what = "element \"" + e.name + "\" (" + std::to_string(e.count) + " rows of " +
                                 std::to_string(row) + " bytes) does not fit in the " + std::to_string(r.remaining()) +
                                 " bytes left";
        if (row != 0 && e.count > r.remaining() / row) fail(path, "truncated file: " + what);
        dst->resize(static_cast<std::size_t>(e.count) * row);
        r.read(dst->data(), dst->size(), what);
    }
    if (r.remaining() != 0)
        fail(path, std::to_string(r.remaining()) + " bytes after the last element: the header's counts do not match the data");

    // Chunk bounds are checked so that every decoded value is a finite float32: a decoded value
    // lies between what its chunk's two bounds decode to (the maps are monotonic), so bounds
    // whose decodes (position, exp of a log scale, SH of a colour) are finite floats suffice.
    // That also keeps the double -> float conversions below in range.
    const std::size_t chunks = static_cast<std::size_t>(L.chunk->count);
    const std::size_t crow = L.chunk->row_size();
    const int nb = L.colour_bounds ? 18 : kGeometryBounds;
    std::vector<double> bounds(chunks * 18, 0.0);
    for (std::size_t c = 0; c < chunks; ++c) {
        for (int k = 0; k < nb; ++k) {
            const double v = ply::load_as_double(chunk_rows.data() + c * crow + L.bounds[k].offset, L.bounds[k].type, swap);
            const double decoded = k < 6 ? v : k < 12 ? std::exp(v) : sh::color_to_dc(v);
            if (!(std::fabs(decoded) <= kMaxDecoded))
                fail(path, "chunk row " + std::to_string(c) + ": \"" + kBoundNames[k] + "\" = " + std::to_string(v) +
                               (k >= 6 && k < 12 ? " (a log scale)" : "") + " is not finite or decodes outside the float32 range");
            bounds[c * 18 + k] = v;
        }
    }

    // The 256 possible SH bytes, decoded once.
    std::array<float, 256> sh_table;
    for (int b = 0; b < 256; ++b) sh_table[static_cast<std::size_t>(b)] = static_cast<float>(decode_sh_byte(static_cast<std::uint8_t>(b)));

    const std::size_t n = static_cast<std::size_t>(L.vertex->count);
    GaussianCloud cloud(n, L.degree);
    const int K = cloud.sh_coeffs();
    const std::size_t vrow = L.vertex->row_size();
    const std::size_t srow = L.sh ? L.sh->row_size() : 0;
    const long long n_ll = static_cast<long long>(n);
#pragma omp parallel for schedule(static)
    for (long long ii = 0; ii < n_ll; ++ii) {
        const std::size_t i = static_cast<std::size_t>(ii);
        const double* b = &bounds[(i / kChunk) * 18];
        const unsigned char* v = vertex_rows.data() + i * vrow;
        const std::uint32_t pp = ply::load<std::uint32_t>(v + L.packed[0], swap);
        const std::uint32_t pr = ply::load<std::uint32_t>(v + L.packed[1], swap);
        const std::uint32_t ps = ply::load<std::uint32_t>(v + L.packed[2], swap);
        const std::uint32_t pc = ply::load<std::uint32_t>(v + L.packed[3], swap);

        const double tp[3] = {unpack_unorm(pp >> 21, 11), unpack_unorm(pp >> 11, 10), unpack_unorm(pp, 11)};
        const double ts[3] = {unpack_unorm(ps >> 21, 11), unpack_unorm(ps >> 11, 10), unpack_unorm(ps, 11)};
        for (int a = 0; a < 3; ++a) {
            cloud.means[3 * i + a] = static_cast<float>(lerp(b[a], b[3 + a], tp[a]));
            cloud.scales[3 * i + a] = static_cast<float>(std::exp(lerp(b[6 + a], b[9 + a], ts[a])));
        }

        const double q3[3] = {(unpack_unorm(pr >> 20, 10) - 0.5) * kInvRotNorm, (unpack_unorm(pr >> 10, 10) - 0.5) * kInvRotNorm,
                              (unpack_unorm(pr, 10) - 0.5) * kInvRotNorm};
        const double largest = std::sqrt(std::max(0.0, 1.0 - (q3[0] * q3[0] + q3[1] * q3[1] + q3[2] * q3[2])));
        const unsigned which = pr >> 30;
        float* q = &cloud.rotations[4 * i];
        for (unsigned k = 0, j = 0; k < 4; ++k) q[k] = static_cast<float>(k == which ? largest : q3[j++]);

        float* sh = &cloud.sh[i * 3 * static_cast<std::size_t>(K)];
        for (int c = 0; c < 3; ++c) {
            const double t = unpack_unorm(pc >> (24 - 8 * c), 8);
            const double colour = L.colour_bounds ? lerp(b[12 + c], b[15 + c], t) : t;
            sh[c] = static_cast<float>(sh::color_to_dc(colour));
        }
        cloud.opacities[i] = static_cast<float>(unpack_unorm(pc, 8));
        if (L.sh) {
            // Channel-major on disk: f_rest_{c(K-1)+j} is coefficient j+1 of channel c.
            const unsigned char* s = sh_rows.data() + i * srow;
            const std::size_t* rest = L.rest.data();
            for (int c = 0; c < 3; ++c)
                for (int j = 1; j < K; ++j) sh[3 * j + c] = sh_table[s[*rest++]];
        }
    }
    return cloud;
}

void put_u32(unsigned char* dst, std::uint32_t v) {
    for (int k = 0; k < 4; ++k) dst[k] = static_cast<unsigned char>(v >> (8 * k));
}

void put_f32(unsigned char* dst, float f) {
    std::uint32_t v;
    std::memcpy(&v, &f, 4);
    put_u32(dst, v);
}

struct MinMax {
    double lo = std::numeric_limits<double>::infinity();
    double hi = -std::numeric_limits<double>::infinity();
    void add(double v) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
    }
};

}  // namespace

GaussianCloud read_compressed_ply(const std::string& path) {
    std::ifstream in;
    const std::uint64_t size = ply::open_ply(in, path);
    return read_stream(in, size, path);
}

GaussianCloud parse_compressed_ply(const unsigned char* data, std::size_t size, const std::string& name) {
    std::istringstream in(std::string(reinterpret_cast<const char*>(data), data ? size : 0));
    return read_stream(in, data ? size : 0, name);
}

void write_compressed_ply(const std::string& path, const GaussianCloud& cloud, bool morton) {
    validate(cloud);
    const std::size_t n = cloud.size();
    const int K = cloud.sh_coeffs();
    // Bounds are the values themselves (positions) or float32 colours 0.5 + C0 * dc: refuse a
    // value whose bound the reader would refuse (log scales are clamped to +-20).
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            const float m = cloud.means[3 * i + a];
            if (!(std::fabs(double(m)) <= kMaxDecoded))
                throw std::invalid_argument(path + ": GaussianCloud.means[" + std::to_string(i) + "][" +
                                            std::to_string(a) + "] = " + std::to_string(m) +
                                            ": compressed PLY stores positions within +-1e38");
            const float dc = cloud.sh[i * 3 * static_cast<std::size_t>(K) + a];
            const float colour = static_cast<float>(sh::dc_to_color<double>(dc));
            if (!(std::fabs(sh::color_to_dc(double(colour))) <= kMaxDecoded))
                throw std::invalid_argument(path + ": GaussianCloud.sh[" + std::to_string(i) + "][0][" +
                                            std::to_string(a) + "] = " + std::to_string(dc) +
                                            ": compressed PLY stores SH DC within about +-1e38");
        }
    const std::size_t R = 3u * static_cast<std::size_t>(K - 1);
    const std::size_t chunks = chunks_for(n);
    std::vector<std::size_t> order;
    if (morton) {
        order = morton_order(cloud);
    } else {
        order.resize(n);
        std::iota(order.begin(), order.end(), std::size_t(0));
    }

    std::string header = "ply\nformat binary_little_endian 1.0\ncomment Generated by avsplat\nelement chunk " +
                         std::to_string(chunks) + "\n";
    for (const char* b : kBoundNames) header += std::string("property float ") + b + "\n";
    header += "element vertex " + std::to_string(n) + "\n";
    for (const char* p : kPackedNames) header += std::string("property uint ") + p + "\n";
    if (R > 0) {
        header += "element sh " + std::to_string(n) + "\n";
        for (std::size_t k = 0; k < R; ++k) header += "property uchar f_rest_" + std::to_string(k) + "\n";
    }
    header += "end_header\n";

    std::vector<unsigned char> chunk_bytes(chunks * 18 * 4), vertex_bytes(n * 16), sh_bytes(n * R);
    const long long chunks_ll = static_cast<long long>(chunks);
#pragma omp parallel for schedule(static)
    for (long long cc = 0; cc < chunks_ll; ++cc) {
        const std::size_t c = static_cast<std::size_t>(cc);
        const std::size_t first = c * kChunk, count = std::min(kChunk, n - first);
        // The values the format quantises, as float32 as splat-transform holds them: positions,
        // log scales (as a 3DGS PLY stores them), colours 0.5 + C0 * dc.
        std::vector<std::array<float, 9>> v(count);
        MinMax mm[9];
        for (std::size_t j = 0; j < count; ++j) {
            const std::size_t i = order[first + j];
            for (int a = 0; a < 3; ++a) {
                v[j][a] = cloud.means[3 * i + a];
                v[j][3 + a] = static_cast<float>(std::log(double(cloud.scales[3 * i + a])));
                v[j][6 + a] = static_cast<float>(sh::dc_to_color<double>(cloud.sh[i * 3 * static_cast<std::size_t>(K) + a]));
            }
            for (int k = 0; k < 9; ++k) mm[k].add(v[j][k]);
        }
        for (int a = 3; a < 6; ++a) {
            mm[a].lo = std::clamp(mm[a].lo, -kLogScaleLimit, kLogScaleLimit);
            mm[a].hi = std::clamp(mm[a].hi, -kLogScaleLimit, kLogScaleLimit);
        }
        // Bounds on disk are float32; every one is a float32 value already (or +-20).
        unsigned char* cb = &chunk_bytes[c * 72];
        for (int g = 0; g < 3; ++g)
            for (int a = 0; a < 3; ++a) {
                put_f32(cb + 4 * (6 * g + a), static_cast<float>(mm[3 * g + a].lo));
                put_f32(cb + 4 * (6 * g + 3 + a), static_cast<float>(mm[3 * g + a].hi));
            }
        for (std::size_t j = 0; j < count; ++j) {
            const std::size_t i = order[first + j];
            std::uint32_t w[4];
            std::uint32_t t[9];
            for (int k = 0; k < 9; ++k) t[k] = pack_unorm(normalize(v[j][k], mm[k].lo, mm[k].hi), k >= 6 ? 8 : k % 3 == 1 ? 10 : 11);
            w[0] = t[0] << 21 | t[1] << 11 | t[2];
            w[2] = t[3] << 21 | t[4] << 11 | t[5];
            w[3] = t[6] << 24 | t[7] << 16 | t[8] << 8 | pack_unorm(cloud.opacities[i], 8);
            // Smallest three: the largest component (first of equals) is made positive and left
            // out; the others are at most sqrt(2)/2 in magnitude.
            const float* qf = &cloud.rotations[4 * i];
            const double norm = std::sqrt(double(qf[0]) * qf[0] + double(qf[1]) * qf[1] + double(qf[2]) * qf[2] + double(qf[3]) * qf[3]);
            double q[4];
            for (int k = 0; k < 4; ++k) q[k] = qf[k] / norm;
            int largest = 0;
            for (int k = 1; k < 4; ++k)
                if (std::fabs(q[k]) > std::fabs(q[largest])) largest = k;
            const double sign = q[largest] < 0 ? -1.0 : 1.0;
            std::uint32_t rot = static_cast<std::uint32_t>(largest);
            for (int k = 0; k < 4; ++k)
                if (k != largest) rot = (rot << 10) | pack_unorm(sign * q[k] * kRotNorm + 0.5, 10);
            w[1] = rot;
            unsigned char* vb = &vertex_bytes[(first + j) * 16];
            for (int k = 0; k < 4; ++k) put_u32(vb + 4 * k, w[k]);
            // SH: channel-major, one byte per coefficient.
            unsigned char* sb = sh_bytes.data() + (first + j) * R;
            const float* sh = &cloud.sh[i * 3 * static_cast<std::size_t>(K)];
            for (int ch = 0; ch < 3; ++ch)
                for (int k = 1; k < K; ++k) *sb++ = encode_sh(sh[3 * k + ch]);
        }
    }

    AtomicFile out(path);
    out.write(header);
    out.write(chunk_bytes.data(), chunk_bytes.size());
    out.write(vertex_bytes.data(), vertex_bytes.size());
    out.write(sh_bytes.data(), sh_bytes.size());
    out.commit();
}

}  // namespace avsplat
