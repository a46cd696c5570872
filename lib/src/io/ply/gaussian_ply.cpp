// Reading the 3DGS parameterisation of PLY (io/ply.h) on the generic PLY primitives
// (ply_format.h): which vertex property lands where in a GaussianCloud, read in bulk.
#include "avsplat/io/ply.h"

#include "avsplat/core/error.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/gaussian_io.h"
#include "common/huge_pages.h"
#include "common/populate_pages.h"
#include "io/ply/gaussian_activations.h"
#include "io/ply/ply_format.h"
#include "io/ply/standard_layout.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <new>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace avsplat {

namespace {

using ply::BinaryReader;
using ply::Element;
using ply::fail;
using ply::Header;
using ply::LineReader;
using ply::Property;

// The 3DGS parameterisation on disk (opacity as a logit, scale as a log) is decoded by
// gaussian_activations.h, which also holds the writer's side (encode_scale, encode_opacity).
using ply::decode_opacity;
using ply::decode_scale;
using ply::copy_standard_rows;
using ply::standard_prefix;

// ---------------------------------------------------------------------------------------------
// Where each vertex property goes.

enum class Dest : std::uint8_t { kDrop, kCopy, kOpacity, kScale };

struct Slot {
    Dest dest = Dest::kDrop;
    PlyType type = PlyType::Float32;
    std::size_t offset = 0;              // byte offset in a binary row
    std::vector<float>* array = nullptr;  // destination array (none for kDrop)
    std::size_t first = 0;               // index of row 0's value in `array`
    std::size_t stride = 0;              // floats between rows
    float* base = nullptr;               // array->data() + first, set once the rows exist
};

// A canonical decimal index ("0", "17"; not "07", "+1" or "-1").
bool parse_index(std::string_view s, int* out) {
    if (s.empty() || s.size() > 3 || (s.size() > 1 && s[0] == '0')) return false;
    if (!std::all_of(s.begin(), s.end(), [](char ch) { return ch >= '0' && ch <= '9'; })) return false;
    const auto r = std::from_chars(s.data(), s.data() + s.size(), *out);
    return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

bool starts_with(std::string_view s, std::string_view prefix) {
    return s.size() >= prefix.size() && s.substr(0, prefix.size()) == prefix;
}

// Sizes `cloud` for n rows and maps every vertex property to its destination.
std::vector<Slot> plan(const Element& vertex, std::size_t n, GaussianCloud& cloud, const std::string& path) {
    // The SH degree follows from the f_rest count: 3 * ((d + 1)^2 - 1) properties.
    int rest = 0;
    for (const auto& p : vertex.properties)
        if (starts_with(p.name, "f_rest_")) ++rest;
    int degree = -1;
    for (int d = 0; d <= kMaxShDegree; ++d)
        if (3 * (sh_coeffs_for_degree(d) - 1) == rest) degree = d;
    if (degree < 0)
        fail(path, "vertex element has " + std::to_string(rest) +
                       " f_rest properties; a 3DGS file has 0, 9, 24 or 45 (SH degree 0..3)");
    const int K = sh_coeffs_for_degree(degree);

    cloud = GaussianCloud();
    cloud.sh_degree = degree;
    // Large arrays are backed by transparent huge pages: filling them then costs a page fault per
    // 2 MiB rather than per 4 KiB (page faults were a fifth of a warm-cache read). The kernel's
    // zeroing of those pages is the largest cost after the copy: it is done on every thread
    // (populate_pages) before resize() value-initialises the arrays on this one, which then
    // writes to present pages (measured for 496 MB on two threads: 53 ms for a fresh resize
    // alone, 22 + 7 ms with the pages populated first).
    std::vector<float>* const arrays[] = {&cloud.means, &cloud.scales, &cloud.rotations, &cloud.opacities, &cloud.sh};
    const std::size_t counts[] = {3 * n, 3 * n, 4 * n, n, n * static_cast<std::size_t>(K) * 3};
    std::vector<ByteRange> fresh;
    for (int k = 0; k < 5; ++k) {
        reserve_huge(*arrays[k], counts[k]);
        fresh.push_back({arrays[k]->data(), counts[k] * sizeof(float)});
    }
    populate_pages(fresh);
    for (int k = 0; k < 5; ++k) arrays[k]->resize(counts[k]);

    struct Required { const char* name; std::vector<float>* array; std::size_t first, stride; Dest dest; bool seen; };
    const std::size_t sh_stride = 3u * static_cast<std::size_t>(K);
    Required req[] = {
        {"x", &cloud.means, 0, 3, Dest::kCopy, false},
        {"y", &cloud.means, 1, 3, Dest::kCopy, false},
        {"z", &cloud.means, 2, 3, Dest::kCopy, false},
        {"f_dc_0", &cloud.sh, 0, sh_stride, Dest::kCopy, false},
        {"f_dc_1", &cloud.sh, 1, sh_stride, Dest::kCopy, false},
        {"f_dc_2", &cloud.sh, 2, sh_stride, Dest::kCopy, false},
        {"opacity", &cloud.opacities, 0, 1, Dest::kOpacity, false},
        {"scale_0", &cloud.scales, 0, 3, Dest::kScale, false},
        {"scale_1", &cloud.scales, 1, 3, Dest::kScale, false},
        {"scale_2", &cloud.scales, 2, 3, Dest::kScale, false},
        {"rot_0", &cloud.rotations, 0, 4, Dest::kCopy, false},
        {"rot_1", &cloud.rotations, 1, 4, Dest::kCopy, false},
        {"rot_2", &cloud.rotations, 2, 4, Dest::kCopy, false},
        {"rot_3", &cloud.rotations, 3, 4, Dest::kCopy, false},
    };

    // Extras are all added before any slot points at one (push_back moves them).
    auto is_known = [&](const std::string& name) {
        if (name == "nx" || name == "ny" || name == "nz" || starts_with(name, "f_rest_")) return true;
        for (const auto& r : req)
            if (name == r.name) return true;
        return false;
    };
    for (const auto& p : vertex.properties) {
        if (p.name == "confidence") cloud.confidence.resize(n);
        else if (!is_known(p.name)) cloud.extras.push_back({p.name, std::vector<float>(n)});
    }

    std::vector<Slot> slots;
    std::size_t offset = 0;
    std::size_t extra = 0;
    for (const auto& p : vertex.properties) {
        Slot s;
        s.type = p.type;
        s.offset = offset;
        offset += ply::type_size(p.type);
        auto r = std::find_if(std::begin(req), std::end(req), [&](const Required& q) { return p.name == q.name; });
        if (r != std::end(req)) {
            s.dest = r->dest;
            s.array = r->array;
            s.first = r->first;
            s.stride = r->stride;
            r->seen = true;
        } else if (p.name == "nx" || p.name == "ny" || p.name == "nz") {
            s.dest = Dest::kDrop;
        } else if (starts_with(p.name, "f_rest_")) {
            // Names are unique (the header parser checks), so `rest` distinct indices below
            // `rest` are exactly 0 .. rest-1.
            int idx = -1;
            if (!parse_index(std::string_view(p.name).substr(7), &idx) || idx >= rest)
                fail(path, "vertex property \"" + p.name + "\": expected f_rest_0 .. f_rest_" + std::to_string(rest - 1));
            // Channel-major on disk: f_rest_{c*(K-1)+j} is coefficient j+1 of channel c.
            const int c = idx / (K - 1);
            const int j = idx % (K - 1);
            s.dest = Dest::kCopy;
            s.array = &cloud.sh;
            s.first = static_cast<std::size_t>(3 * (j + 1) + c);
            s.stride = sh_stride;
        } else if (p.name == "confidence") {
            s.dest = Dest::kCopy;
            s.array = &cloud.confidence;
            s.stride = 1;
        } else {
            s.dest = Dest::kCopy;
            s.array = &cloud.extras[extra++].values;
            s.stride = 1;
        }
        slots.push_back(s);
    }
    for (const auto& r : req)
        if (!r.seen) fail(path, "vertex element has no \"" + std::string(r.name) + "\" property");
    // Pointers only into arrays that hold rows (an empty vector's data() may be null).
    if (n > 0)
        for (auto& s : slots)
            if (s.array) s.base = s.array->data() + s.first;
    return slots;
}

void store(const Slot& s, std::size_t row, double v) {
    float* dst = s.base + row * s.stride;
    switch (s.dest) {
        case Dest::kDrop: break;
        case Dest::kCopy: *dst = static_cast<float>(v); break;
        // A float on disk decodes from its exact value; a double from its full precision.
        case Dest::kOpacity: *dst = decode_opacity(v); break;
        case Dest::kScale: *dst = decode_scale(v); break;
    }
}


// Decodes the binary vertex rows of one read, a piece at a time.
class RowDecoder {
public:
    RowDecoder(const Element& vertex, bool swap, const std::vector<Slot>& slots, GaussianCloud& cloud)
        : row_(vertex.row_size()), swap_(swap), slots_(slots) {
        float_native_ = !swap && std::all_of(slots.begin(), slots.end(), [](const Slot& s) {
            return s.type == PlyType::Float32;
        });
        K_ = cloud.sh_coeffs();
        prefix_ = standard_prefix(vertex, swap, K_, &normals_);
        out_ = {cloud.means.data(), cloud.sh.data(), cloud.opacities.data(), cloud.scales.data(), cloud.rotations.data()};
        // Native float32: every value is copied as stored, opacities and scales decoded after.
        if (float_native_)
            for (std::size_t k = prefix_; k < slots.size(); ++k)
                if (slots[k].dest != Dest::kDrop) copies_.push_back({slots[k].offset, slots[k].base, slots[k].stride});
    }

    // Decodes `rows` rows at `src`, rows first .. first + rows - 1 of the file.
    void decode(const unsigned char* src, std::size_t first, std::size_t rows) const {
        if (!float_native_) {
            for (std::size_t k = 0; k < rows; ++k, src += row_)
                for (const Slot& s : slots_) store(s, first + k, ply::load_as_double(src + s.offset, s.type, swap_));
            return;
        }
        if (prefix_ > 0) copy_prefix(src, first, rows);
        // The other properties row by row: a row's destinations are a few dense runs.
        if (!copies_.empty()) {
            const unsigned char* r = src;
            for (std::size_t i = first; i < first + rows; ++i, r += row_)
                for (const Copy& c : copies_) std::memcpy(c.base + i * c.stride, r + c.offset, sizeof(float));
        }
        ply::decode_opacities(out_.opacities + first, rows);
        ply::decode_scales(out_.scales + 3 * first, 3 * rows);
    }

private:
    struct Copy {
        std::size_t offset;
        float* base;
        std::size_t stride;
    };

    void copy_prefix(const unsigned char* src, std::size_t first, std::size_t rows) const {
        switch (K_ * 2 + (normals_ ? 1 : 0)) {
            case 1 * 2: return copy_standard_rows<1, false>(src, row_, first, rows, out_);
            case 1 * 2 + 1: return copy_standard_rows<1, true>(src, row_, first, rows, out_);
            case 4 * 2: return copy_standard_rows<4, false>(src, row_, first, rows, out_);
            case 4 * 2 + 1: return copy_standard_rows<4, true>(src, row_, first, rows, out_);
            case 9 * 2: return copy_standard_rows<9, false>(src, row_, first, rows, out_);
            case 9 * 2 + 1: return copy_standard_rows<9, true>(src, row_, first, rows, out_);
            case 16 * 2: return copy_standard_rows<16, false>(src, row_, first, rows, out_);
            default: return copy_standard_rows<16, true>(src, row_, first, rows, out_);
        }
    }

    std::size_t row_;
    bool swap_;
    const std::vector<Slot>& slots_;
    bool float_native_ = false;
    int K_ = 1;
    bool normals_ = false;
    std::size_t prefix_ = 0;
    ply::StandardOutputs out_{};
    std::vector<Copy> copies_;
};

// Reads the n vertex rows that start at byte `offset` of the file. Each thread reads its own
// range of rows with pread, a cache-sized piece at a time, and decodes the piece while it is in
// cache: the copy out of the page cache runs on every thread and overlaps the decoding, which a
// serial read followed by a parallel decode did not. (No mmap: a file truncated while mapped
// would kill the process with SIGBUS, where pread reports a short read.)
void read_binary_vertices(const std::string& path, std::uint64_t offset, const Element& vertex,
                          const RowDecoder& decoder, std::size_t n) {
    const std::size_t row = vertex.row_size();
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail(path, std::string("cannot open for reading: ") + std::strerror(errno));
    struct Close {
        int fd;
        ~Close() { ::close(fd); }
    } close_fd{fd};
    ::posix_fadvise(fd, static_cast<off_t>(offset), static_cast<off_t>(n * row), POSIX_FADV_SEQUENTIAL);
    const std::size_t rows_per_piece = std::max<std::size_t>(1, (128u << 10) / row);
    const std::size_t pieces = (n + rows_per_piece - 1) / rows_per_piece;
    std::string error;  // the first piece's error, in piece order
    std::size_t error_piece = pieces;
#pragma omp parallel if (n * row >= (4u << 20))
    {
        std::vector<unsigned char> buf;
        std::size_t my_error_piece = pieces;
        std::string my_error;
#pragma omp for schedule(static)
        for (long long p = 0; p < static_cast<long long>(pieces); ++p) {
            if (my_error_piece < pieces) continue;
            const std::size_t first = static_cast<std::size_t>(p) * rows_per_piece;
            const std::size_t rows = std::min(rows_per_piece, n - first);
            const std::size_t bytes = rows * row;
            try {
                if (buf.size() < bytes) buf.resize(bytes);
                std::size_t got = 0;
                while (got < bytes) {
                    const ssize_t r = ::pread(fd, buf.data() + got, bytes - got,
                                              static_cast<off_t>(offset + first * row + got));
                    if (r < 0 && errno == EINTR) continue;
                    if (r <= 0) {
                        my_error = (r < 0 ? "read error: " + std::string(std::strerror(errno)) + ": "
                                          : std::string("truncated file (it shrank while being read): ")) +
                                   "vertex rows " + std::to_string(first) + ".." + std::to_string(first + rows - 1);
                        my_error_piece = static_cast<std::size_t>(p);
                        break;
                    }
                    got += static_cast<std::size_t>(r);
                }
                if (my_error_piece == pieces) decoder.decode(buf.data(), first, rows);
            } catch (const std::bad_alloc&) {
                my_error = "out of memory reading vertex rows";
                my_error_piece = static_cast<std::size_t>(p);
            }
        }
#pragma omp critical(avsplat_ply_read)
        if (my_error_piece < error_piece) {
            error_piece = my_error_piece;
            error = my_error;
        }
    }
    if (error_piece < pieces) fail(path, error);
}

void read_ascii(std::istream& in, const Header& h, std::size_t vertex_index, GaussianCloud& cloud,
                const std::string& path) {
    LineReader lines(in, path);
    std::string_view line;
    for (std::size_t k = 0; k < vertex_index; ++k) {
        const Element& e = h.elements[k];
        for (std::uint64_t i = 0; i < e.count; ++i) {
            if (!lines.next(&line))
                fail(path, "truncated file: element \"" + e.name + "\" has " + std::to_string(i) + " of " +
                               std::to_string(e.count) + " rows");
        }
    }
    const Element& vertex = h.elements[vertex_index];
    const std::vector<Property>& props = vertex.properties;
    const std::size_t P = props.size();

    // Values are appended as they are parsed (the header count is not trusted for an
    // allocation), then decoded with the same slots as the binary path once the rows are known.
    std::vector<double> values;
    std::vector<std::string_view> tok;
    std::uint64_t rows = 0;
    for (; rows < vertex.count; ++rows) {
        if (!lines.next(&line))
            fail(path, "truncated file: vertex element has " + std::to_string(rows) + " of " +
                           std::to_string(vertex.count) + " rows");
        tok = ply::split_ws(line);
        const std::string where = "vertex row " + std::to_string(rows) + " (data line " + std::to_string(lines.line_no()) + ")";
        if (tok.size() != P)
            fail(path, where + " has " + std::to_string(tok.size()) + " values, expected " + std::to_string(P));
        for (std::size_t k = 0; k < P; ++k) {
            double v = 0;
            if (!ply::parse_ascii_value(tok[k], props[k].type, &v))
                fail(path, where + ": \"" + std::string(tok[k]) + "\" is not a valid value of property \"" +
                               props[k].name + "\"");
            values.push_back(v);
        }
    }
    // The elements after the vertex element must be there in full (one line per row), and
    // nothing after them.
    for (std::size_t k = vertex_index + 1; k < h.elements.size(); ++k) {
        const Element& e = h.elements[k];
        for (std::uint64_t i = 0; i < e.count; ++i) {
            if (!lines.next(&line))
                fail(path, "truncated file: element \"" + e.name + "\" has " + std::to_string(i) + " of " +
                               std::to_string(e.count) + " rows");
        }
    }
    if (lines.next(&line)) {
        if (vertex_index + 1 == h.elements.size())
            fail(path, "data line " + std::to_string(lines.line_no()) + " after the last of the " +
                           std::to_string(vertex.count) + " vertex rows: the header's count does not match the data");
        fail(path, "data line " + std::to_string(lines.line_no()) +
                       " after the rows of the last element: the header's counts do not match the data");
    }
    const std::size_t n = static_cast<std::size_t>(rows);
    const std::vector<Slot> slots = plan(vertex, n, cloud, path);
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t k = 0; k < P; ++k) store(slots[k], i, values[i * P + k]);
}

}  // namespace

namespace {

// A file of another Gaussian format (SPZ, SOG, .splat) fails on its first bytes; name the format
// it is instead of the first thing in it that is not PLY.
void refuse_other_format(const std::string& path) {
    char magic[4] = {};
    std::ifstream probe(path, std::ios::binary);
    probe.read(magic, 4);
    if (probe.gcount() == 4 && std::memcmp(magic, "ply", 3) == 0 && (magic[3] == '\n' || magic[3] == '\r')) return;
    GaussianFormatInfo f;
    try {
        f = detect_gaussian_format(path);
    } catch (const IOError&) {
        return;  // no known format: the PLY reader's own message says what is wrong
    }
    if (f.format != GaussianFormat::Ply)
        throw IOError(path + ": not a PLY file: it looks like a " + f.name +
                      " file (read_gaussians reads every format, detected from the content)");
}

}  // namespace

GaussianCloud read_ply(const std::string& path) {
    std::ifstream in;
    const std::uint64_t size = ply::open_ply(in, path);
    refuse_other_format(path);

    const Header h = ply::read_header(in, path);
    std::size_t vertex_index = h.elements.size();
    for (std::size_t k = 0; k < h.elements.size(); ++k)
        if (h.elements[k].name == "vertex") vertex_index = k;
    if (vertex_index == h.elements.size()) fail(path, "no \"vertex\" element");
    const Element& vertex = h.elements[vertex_index];
    // PlayCanvas's compressed PLY is recognised by its content (splat-transform's marker), so
    // that it opens whatever the file is called.
    for (const auto& p : vertex.properties)
        if (p.name == "packed_position") return read_compressed_ply(path);
    for (const auto& p : vertex.properties)
        if (p.is_list) fail(path, "vertex property \"" + p.name + "\" is a list; 3DGS vertex properties are scalars");
    {
        // Header problems (missing or misnamed properties) are reported before any data is read.
        GaussianCloud probe;
        plan(vertex, 0, probe, path);
    }

    GaussianCloud cloud;
    if (h.format == PlyFormat::Ascii) {
        read_ascii(in, h, vertex_index, cloud, path);
        return cloud;
    }

    const bool swap = (h.format == PlyFormat::BinaryBigEndian) == ply::kHostLittleEndian;
    BinaryReader r(in, static_cast<std::uint64_t>(size) - h.data_offset, path);
    for (std::size_t k = 0; k < vertex_index; ++k) ply::skip_binary_element(r, h.elements[k], swap);

    const std::size_t row = vertex.row_size();
    if (row == 0) fail(path, "vertex element has no properties");
    if (vertex.count > r.remaining() / row)
        fail(path, "truncated file or bad vertex count: " + std::to_string(vertex.count) + " vertices of " +
                       std::to_string(row) + " bytes need more than the " + std::to_string(r.remaining()) +
                       " bytes left in the file");
    const std::size_t n = static_cast<std::size_t>(vertex.count);
    const std::vector<Slot> slots = plan(vertex, n, cloud, path);
    read_binary_vertices(path, size - r.remaining(), vertex, RowDecoder(vertex, swap, slots, cloud), n);
    r.skip(n * row, "vertex rows");

    // Elements after the vertex element do not affect the result, but the file must hold exactly
    // them: a file cut short (a header declaring "element face 5" with no face data) or a header
    // count that is too small is reported rather than silently accepted. Rows with lists are
    // walked, so they cost time in proportion to their count.
    for (std::size_t k = vertex_index + 1; k < h.elements.size(); ++k)
        ply::skip_binary_element(r, h.elements[k], swap);
    if (r.remaining() > 0)
        fail(path, std::to_string(r.remaining()) +
                       " bytes after the last element: the header's counts do not match the data");
    return cloud;
}

}  // namespace avsplat
