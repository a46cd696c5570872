#include "avsplat/io/ply.h"

#include "avsplat/core/error.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace avsplat {

namespace {

[[noreturn]] void fail(const std::string& path, const std::string& what) {
    throw IOError(path + ": " + what);
}

// ---------------------------------------------------------------------------------------------
// The 3DGS parameterisation on disk: opacity as a logit, scale as a log, both float32.
//
// Both directions compute in double and round once to float. Decoding a float32 L is then
// correctly rounded, and the writer's L is the float nearest the exact log / logit, whose decode
// is the nearest to the value in memory that any float32 L gives (a search over neighbouring
// floats found no better L in 4 million random values). Exactness is limited by float32 on disk,
// not by the arithmetic: below 1/e there are about 4x fewer float32 logs than float32 scales,
// so not every scale can come back bit-exact. Measured (tests/cpp/test_ply.cpp): bit-exact for
// scales in [1/e, e] and opacities in [0.25, 1]; at most 8 ulp for scales in [1e-6, 1e3] and
// opacities in [1e-6, 1] (half the gap between the decodes of neighbouring floats L).

float decode_scale(double log_scale) { return static_cast<float>(std::exp(log_scale)); }

float decode_opacity(double l) {
    if (l >= 0.0) return static_cast<float>(1.0 / (1.0 + std::exp(-l)));
    const double e = std::exp(l);
    return static_cast<float>(e / (1.0 + e));
}

// 0 gives -inf, which decodes back to 0.
float encode_scale(float s) { return static_cast<float>(std::log(static_cast<double>(s))); }

float encode_opacity(float p) {
    const double pd = p;
    // log(p) - log1p(-p) keeps the precision of p near both ends; 0 and 1 give -inf and +inf.
    return static_cast<float>(std::log(pd) - std::log1p(-pd));
}

// ---------------------------------------------------------------------------------------------
// PLY header model.

enum class Format { kAscii, kBinaryLittle, kBinaryBig };

enum class Type : std::uint8_t { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

bool parse_type(std::string_view s, Type* t) {
    static const std::pair<const char*, Type> kNames[] = {
        {"char", Type::kInt8},     {"int8", Type::kInt8},       {"uchar", Type::kUInt8},
        {"uint8", Type::kUInt8},   {"short", Type::kInt16},     {"int16", Type::kInt16},
        {"ushort", Type::kUInt16}, {"uint16", Type::kUInt16},   {"int", Type::kInt32},
        {"int32", Type::kInt32},   {"uint", Type::kUInt32},     {"uint32", Type::kUInt32},
        {"float", Type::kFloat32}, {"float32", Type::kFloat32}, {"double", Type::kFloat64},
        {"float64", Type::kFloat64}};
    for (const auto& [name, type] : kNames) {
        if (s == name) {
            *t = type;
            return true;
        }
    }
    return false;
}

std::size_t type_size(Type t) {
    switch (t) {
        case Type::kInt8: case Type::kUInt8: return 1;
        case Type::kInt16: case Type::kUInt16: return 2;
        case Type::kInt32: case Type::kUInt32: case Type::kFloat32: return 4;
        case Type::kFloat64: return 8;
    }
    return 0;
}

bool is_integer(Type t) { return t != Type::kFloat32 && t != Type::kFloat64; }

struct Property {
    std::string name;
    Type type = Type::kFloat32;
    bool is_list = false;
    Type count_type = Type::kUInt8;  // lists only
};

struct Element {
    std::string name;
    std::uint64_t count = 0;
    std::vector<Property> properties;

    bool has_lists() const {
        return std::any_of(properties.begin(), properties.end(), [](const Property& p) { return p.is_list; });
    }
    // Bytes per row in a binary file; only meaningful without list properties.
    std::size_t row_size() const {
        std::size_t s = 0;
        for (const auto& p : properties) s += type_size(p.type);
        return s;
    }
};

struct Header {
    Format format = Format::kAscii;
    std::vector<Element> elements;
    std::uint64_t data_offset = 0;  // first byte after "end_header\n"
};

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::vector<std::string_view> split_ws(std::string_view line) {
    std::vector<std::string_view> out;
    std::size_t i = 0;
    while (i < line.size()) {
        while (i < line.size() && is_space(line[i])) ++i;
        std::size_t j = i;
        while (j < line.size() && !is_space(line[j])) ++j;
        if (j > i) out.push_back(line.substr(i, j - i));
        i = j;
    }
    return out;
}

// Longest header line we accept; a real header line is a few dozen characters. Bounding it keeps
// a non-PLY file from being read into memory as one huge "line".
constexpr std::size_t kMaxHeaderLine = 4096;
// Headers are a few kilobytes; this bounds the time spent on a file that never says end_header.
constexpr int kMaxHeaderLines = 100000;

Header read_header(std::istream& in, const std::string& path) {
    Header h;
    char buf[kMaxHeaderLine + 1];
    int line_no = 0;
    auto next_line = [&](std::string_view* line) {
        in.getline(buf, sizeof buf);
        if (in.fail()) {
            if (in.eof() && in.gcount() == 0) return false;  // nothing left
            fail(path, "header line " + std::to_string(line_no + 1) + " is longer than " +
                           std::to_string(kMaxHeaderLine) + " bytes (not a PLY header)");
        }
        ++line_no;
        // gcount counts the newline too, unless the line ended at the end of the file.
        const std::size_t n = static_cast<std::size_t>(in.gcount()) - (in.eof() ? 0 : 1);
        if (std::strlen(buf) != n) fail(path, "NUL byte in header line " + std::to_string(line_no));
        std::string_view s(buf, n);
        if (!s.empty() && s.back() == '\r') s.remove_suffix(1);  // files written on Windows
        *line = s;
        return true;
    };

    std::string_view line;
    if (!next_line(&line) || line != "ply") fail(path, "not a PLY file (the first line is not \"ply\")");

    bool have_format = false;
    bool ended = false;
    while (!ended) {
        if (line_no >= kMaxHeaderLines) fail(path, "header has no end_header within " + std::to_string(kMaxHeaderLines) + " lines");
        if (!next_line(&line)) fail(path, "header ends before end_header (truncated file?)");
        const std::string where = "header line " + std::to_string(line_no) + " \"" + std::string(line) + "\": ";
        const auto tok = split_ws(line);
        if (tok.empty()) continue;
        const std::string_view key = tok[0];
        if (key == "comment" || key == "obj_info") continue;
        if (key == "end_header") {
            if (tok.size() != 1) fail(path, where + "unexpected text after end_header");
            ended = true;
        } else if (key == "format") {
            if (have_format) fail(path, where + "second format line");
            if (!h.elements.empty()) fail(path, where + "format after an element");
            if (tok.size() != 3) fail(path, where + "expected \"format <type> 1.0\"");
            if (tok[1] == "ascii") h.format = Format::kAscii;
            else if (tok[1] == "binary_little_endian") h.format = Format::kBinaryLittle;
            else if (tok[1] == "binary_big_endian") h.format = Format::kBinaryBig;
            else fail(path, where + "unknown format \"" + std::string(tok[1]) + "\"");
            if (tok[2] != "1.0") fail(path, where + "unsupported PLY version \"" + std::string(tok[2]) + "\"");
            have_format = true;
        } else if (key == "element") {
            if (!have_format) fail(path, where + "element before the format line");
            if (tok.size() != 3) fail(path, where + "expected \"element <name> <count>\"");
            Element e;
            e.name = std::string(tok[1]);
            const auto r = std::from_chars(tok[2].data(), tok[2].data() + tok[2].size(), e.count);
            if (r.ec != std::errc() || r.ptr != tok[2].data() + tok[2].size())
                fail(path, where + "element count is not a non-negative integer that fits 64 bits");
            for (const auto& other : h.elements)
                if (other.name == e.name) fail(path, where + "duplicate element \"" + e.name + "\"");
            h.elements.push_back(std::move(e));
        } else if (key == "property") {
            if (h.elements.empty()) fail(path, where + "property before any element");
            Property p;
            if (tok.size() == 5 && tok[1] == "list") {
                p.is_list = true;
                if (!parse_type(tok[2], &p.count_type) || !parse_type(tok[3], &p.type))
                    fail(path, where + "unknown property type");
                if (!is_integer(p.count_type)) fail(path, where + "list count type must be an integer type");
                p.name = std::string(tok[4]);
            } else if (tok.size() == 3 && tok[1] != "list") {
                if (!parse_type(tok[1], &p.type)) fail(path, where + "unknown property type \"" + std::string(tok[1]) + "\"");
                p.name = std::string(tok[2]);
            } else {
                fail(path, where + "expected \"property <type> <name>\" or \"property list <type> <type> <name>\"");
            }
            auto& props = h.elements.back().properties;
            for (const auto& other : props)
                if (other.name == p.name) fail(path, where + "duplicate property \"" + p.name + "\"");
            props.push_back(std::move(p));
        } else {
            fail(path, where + "unknown keyword \"" + std::string(key) + "\"");
        }
    }
    if (!have_format) fail(path, "header has no format line");
    // A file may end right after "end_header" without a newline; then there is no data.
    if (in.eof()) {
        in.clear();
        in.seekg(0, std::ios::end);
    }
    const std::streamoff offset = in.tellg();
    if (offset < 0) fail(path, "read error after the header");
    h.data_offset = static_cast<std::uint64_t>(offset);
    return h;
}

// ---------------------------------------------------------------------------------------------
// Where each vertex property goes.

enum class Dest : std::uint8_t { kDrop, kCopy, kOpacity, kScale };

struct Slot {
    Dest dest = Dest::kDrop;
    Type type = Type::kFloat32;
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
    cloud.means.resize(3 * n);
    cloud.scales.resize(3 * n);
    cloud.rotations.resize(4 * n);
    cloud.opacities.resize(n);
    cloud.sh.resize(n * static_cast<std::size_t>(K) * 3);

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
        offset += type_size(p.type);
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

// ---------------------------------------------------------------------------------------------
// Binary data.

constexpr bool kHostLittleEndian = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

template <class T>
T load(const unsigned char* p, bool swap) {
    unsigned char b[sizeof(T)];
    if (swap) {
        for (std::size_t k = 0; k < sizeof(T); ++k) b[k] = p[sizeof(T) - 1 - k];
    } else {
        std::memcpy(b, p, sizeof(T));
    }
    T v;
    std::memcpy(&v, b, sizeof(T));
    return v;
}

double load_as_double(const unsigned char* p, Type t, bool swap) {
    switch (t) {
        case Type::kInt8: return load<std::int8_t>(p, swap);
        case Type::kUInt8: return load<std::uint8_t>(p, swap);
        case Type::kInt16: return load<std::int16_t>(p, swap);
        case Type::kUInt16: return load<std::uint16_t>(p, swap);
        case Type::kInt32: return load<std::int32_t>(p, swap);
        case Type::kUInt32: return load<std::uint32_t>(p, swap);
        case Type::kFloat32: return load<float>(p, swap);
        case Type::kFloat64: return load<double>(p, swap);
    }
    return 0.0;
}

// A list count read from a binary file; negative counts are malformed.
std::uint64_t load_count(const unsigned char* p, Type t, bool swap) {
    const double v = load_as_double(p, t, swap);
    return v < 0 ? std::numeric_limits<std::uint64_t>::max() : static_cast<std::uint64_t>(v);
}

class BinaryReader {
public:
    BinaryReader(std::istream& in, std::uint64_t remaining, const std::string& path)
        : in_(in), remaining_(remaining), path_(path) {}

    std::uint64_t remaining() const { return remaining_; }
    const std::string& path() const { return path_; }

    void read(void* dst, std::uint64_t n, const std::string& what) {
        if (n > remaining_) fail(path_, "truncated file: " + what);
        in_.read(static_cast<char*>(dst), static_cast<std::streamsize>(n));
        if (static_cast<std::uint64_t>(in_.gcount()) != n) fail(path_, "read error: " + what);
        remaining_ -= n;
    }

    void skip(std::uint64_t n, const std::string& what) {
        if (n > remaining_) fail(path_, "truncated file: " + what);
        in_.seekg(static_cast<std::streamoff>(n), std::ios::cur);
        if (!in_) fail(path_, "seek error: " + what);
        remaining_ -= n;
    }

private:
    std::istream& in_;
    std::uint64_t remaining_;
    const std::string& path_;
};

// Skips an element that precedes the vertex element.
void skip_binary_element(BinaryReader& r, const Element& e, bool swap) {
    const std::string what = "element \"" + e.name + "\" (" + std::to_string(e.count) + " rows) does not fit in the file";
    if (!e.has_lists()) {
        const std::size_t row = e.row_size();
        if (row != 0 && e.count > r.remaining() / row) fail(r.path(), "truncated file: " + what);
        r.skip(e.count * row, what);
        return;
    }
    // Rows with lists have no fixed size; each row holds at least one count byte, so the
    // walk ends at the end of the file at the latest.
    for (std::uint64_t i = 0; i < e.count; ++i) {
        for (const auto& p : e.properties) {
            if (!p.is_list) {
                r.skip(type_size(p.type), what);
                continue;
            }
            unsigned char b[8];
            r.read(b, type_size(p.count_type), what);
            const std::uint64_t n = load_count(b, p.count_type, swap);
            const std::size_t item = type_size(p.type);
            if (n > r.remaining() / item) fail(r.path(), "truncated file: " + what);
            r.skip(n * item, what);
        }
    }
}

void read_binary_vertices(BinaryReader& r, const Element& vertex, bool swap, const std::vector<Slot>& slots,
                          std::size_t n) {
    const std::size_t row = vertex.row_size();
    // Bulk reads of whole rows, a few megabytes at a time, then a per-row decode.
    const std::size_t rows_per_chunk = std::max<std::size_t>(1, (8u << 20) / row);
    std::vector<unsigned char> buf(std::min(n, rows_per_chunk) * row);
    const bool all_float_native = !swap && std::all_of(slots.begin(), slots.end(), [](const Slot& s) {
        return s.type == Type::kFloat32;
    });
    for (std::size_t first = 0; first < n; first += rows_per_chunk) {
        const std::size_t rows = std::min(rows_per_chunk, n - first);
        r.read(buf.data(), rows * row,
               "vertex rows " + std::to_string(first) + ".." + std::to_string(first + rows - 1) + " are missing");
        const long long rows_ll = static_cast<long long>(rows);
#pragma omp parallel for schedule(static)
        for (long long k = 0; k < rows_ll; ++k) {
            const unsigned char* src = buf.data() + static_cast<std::size_t>(k) * row;
            const std::size_t i = first + static_cast<std::size_t>(k);
            if (all_float_native) {  // the common case: every property a native float32
                for (const Slot& s : slots) {
                    float v;
                    std::memcpy(&v, src + s.offset, sizeof v);
                    float* dst = s.base + i * s.stride;
                    switch (s.dest) {
                        case Dest::kDrop: break;
                        case Dest::kCopy: *dst = v; break;
                        case Dest::kOpacity: *dst = decode_opacity(v); break;
                        case Dest::kScale: *dst = decode_scale(v); break;
                    }
                }
            } else {
                for (const Slot& s : slots) store(s, i, load_as_double(src + s.offset, s.type, swap));
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// ASCII data.

class LineReader {
public:
    LineReader(std::istream& in, const std::string& path) : in_(in), path_(path) {}

    // The next line that is not blank; false at the end of the file.
    bool next(std::string_view* line) {
        for (;;) {
            if (!fetch(line)) return false;
            ++line_no_;
            if (line->find_first_not_of(" \t\r") != std::string_view::npos) return true;
        }
    }

    // Line number in the data section (1 = first line after end_header).
    std::uint64_t line_no() const { return line_no_; }

private:
    bool fetch(std::string_view* line) {
        for (;;) {
            const auto nl = std::find(buf_.begin() + static_cast<std::ptrdiff_t>(pos_), buf_.end(), '\n');
            if (nl != buf_.end()) {
                const std::size_t end = static_cast<std::size_t>(nl - buf_.begin());
                *line = std::string_view(buf_.data() + pos_, end - pos_);
                pos_ = end + 1;
                return true;
            }
            if (eof_) {
                if (pos_ == buf_.size()) return false;
                *line = std::string_view(buf_.data() + pos_, buf_.size() - pos_);
                pos_ = buf_.size();
                return true;
            }
            // Refill: keep the partial line, append the next block.
            buf_.erase(0, pos_);
            pos_ = 0;
            if (buf_.size() > kMaxLine)
                fail(path_, "ASCII data line " + std::to_string(line_no_ + 1) + " is longer than " +
                                std::to_string(kMaxLine) + " bytes");
            const std::size_t old = buf_.size();
            buf_.resize(old + kBlock);
            in_.read(&buf_[old], kBlock);
            const std::size_t got = static_cast<std::size_t>(in_.gcount());
            buf_.resize(old + got);
            if (got < kBlock) eof_ = true;
        }
    }

    static constexpr std::size_t kBlock = 1u << 20;
    static constexpr std::size_t kMaxLine = 1u << 20;
    std::istream& in_;
    const std::string& path_;
    std::string buf_;
    std::size_t pos_ = 0;
    bool eof_ = false;
    std::uint64_t line_no_ = 0;
};

bool parse_ascii_value(std::string_view tok, Type t, double* out) {
    const char* b = tok.data();
    const char* e = tok.data() + tok.size();
    if (b != e && *b == '+') ++b;  // from_chars does not take a leading '+'
    if (b == e || *b == '+' || (*b == '-' && tok[0] == '+')) return false;
    if (is_integer(t)) {
        long long v = 0;
        const auto r = std::from_chars(b, e, v);
        if (r.ec != std::errc() || r.ptr != e) return false;
        long long lo = 0, hi = 0;
        switch (t) {
            case Type::kInt8: lo = INT8_MIN; hi = INT8_MAX; break;
            case Type::kUInt8: lo = 0; hi = UINT8_MAX; break;
            case Type::kInt16: lo = INT16_MIN; hi = INT16_MAX; break;
            case Type::kUInt16: lo = 0; hi = UINT16_MAX; break;
            case Type::kInt32: lo = INT32_MIN; hi = INT32_MAX; break;
            default: lo = 0; hi = UINT32_MAX; break;
        }
        if (v < lo || v > hi) return false;
        *out = static_cast<double>(v);
        return true;
    }
    // Parse float properties as float so that a decimal float32 reads back to the same bits
    // (decimal -> double -> float can round twice).
    if (t == Type::kFloat32) {
        float v = 0;
        const auto r = std::from_chars(b, e, v);
        if (r.ptr != e) return false;
        if (r.ec == std::errc::result_out_of_range) {
            // Outside float's range (e.g. 1e-50 or 1e40 written from a double): round the
            // double value as a binary reader would, to 0 or +-inf.
            double d = 0;
            const auto rd = std::from_chars(b, e, d);
            if (rd.ec != std::errc() || rd.ptr != e) return false;
            v = static_cast<float>(d);
        } else if (r.ec != std::errc()) {
            return false;
        }
        *out = v;
        return true;
    }
    double v = 0;
    const auto r = std::from_chars(b, e, v);
    if (r.ec != std::errc() || r.ptr != e) return false;
    *out = v;
    return true;
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
        tok = split_ws(line);
        const std::string where = "vertex row " + std::to_string(rows) + " (data line " + std::to_string(lines.line_no()) + ")";
        if (tok.size() != P)
            fail(path, where + " has " + std::to_string(tok.size()) + " values, expected " + std::to_string(P));
        for (std::size_t k = 0; k < P; ++k) {
            double v = 0;
            if (!parse_ascii_value(tok[k], props[k].type, &v))
                fail(path, where + ": \"" + std::string(tok[k]) + "\" is not a valid value of property \"" +
                               props[k].name + "\"");
            values.push_back(v);
        }
    }
    if (vertex_index + 1 == h.elements.size() && lines.next(&line))
        fail(path, "data line " + std::to_string(lines.line_no()) + " after the last of the " +
                       std::to_string(vertex.count) + " vertex rows: the header's count does not match the data");
    const std::size_t n = static_cast<std::size_t>(rows);
    const std::vector<Slot> slots = plan(vertex, n, cloud, path);
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t k = 0; k < P; ++k) store(slots[k], i, values[i * P + k]);
}

}  // namespace

GaussianCloud read_ply(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) fail(path, "cannot open for reading");
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    in.seekg(0, std::ios::beg);
    if (size < 0 || !in) fail(path, "cannot determine the file size");
    if (size == 0) fail(path, "empty file (not a PLY file)");

    const Header h = read_header(in, path);
    std::size_t vertex_index = h.elements.size();
    for (std::size_t k = 0; k < h.elements.size(); ++k)
        if (h.elements[k].name == "vertex") vertex_index = k;
    if (vertex_index == h.elements.size()) fail(path, "no \"vertex\" element");
    const Element& vertex = h.elements[vertex_index];
    for (const auto& p : vertex.properties)
        if (p.is_list) fail(path, "vertex property \"" + p.name + "\" is a list; 3DGS vertex properties are scalars");
    {
        // Header problems (missing or misnamed properties) are reported before any data is read.
        GaussianCloud probe;
        plan(vertex, 0, probe, path);
    }

    GaussianCloud cloud;
    if (h.format == Format::kAscii) {
        read_ascii(in, h, vertex_index, cloud, path);
        return cloud;
    }

    const bool swap = (h.format == Format::kBinaryBig) == kHostLittleEndian;
    BinaryReader r(in, static_cast<std::uint64_t>(size) - h.data_offset, path);
    for (std::size_t k = 0; k < vertex_index; ++k) skip_binary_element(r, h.elements[k], swap);

    const std::size_t row = vertex.row_size();
    if (row == 0) fail(path, "vertex element has no properties");
    if (vertex.count > r.remaining() / row)
        fail(path, "truncated file or bad vertex count: " + std::to_string(vertex.count) + " vertices of " +
                       std::to_string(row) + " bytes need more than the " + std::to_string(r.remaining()) +
                       " bytes left in the file");
    const std::size_t n = static_cast<std::size_t>(vertex.count);
    const std::vector<Slot> slots = plan(vertex, n, cloud, path);
    read_binary_vertices(r, vertex, swap, slots, n);

    // Elements after the vertex element do not affect the result, but when their size is known
    // the file must hold exactly them: a file cut short or a header count that is too small is
    // reported rather than silently accepted.
    std::uint64_t after = 0;
    bool sized = true;
    for (std::size_t k = vertex_index + 1; k < h.elements.size() && sized; ++k) {
        const Element& e = h.elements[k];
        if (e.has_lists()) {
            sized = false;
            break;
        }
        const std::size_t rs = e.row_size();
        if (rs != 0 && e.count > (r.remaining() - after) / rs)
            fail(path, "truncated file: element \"" + e.name + "\" (" + std::to_string(e.count) +
                           " rows) does not fit in the file");
        after += e.count * rs;
    }
    if (sized && r.remaining() > after)
        fail(path, std::to_string(r.remaining() - after) +
                       " bytes after the last element: the header's counts do not match the data");
    return cloud;
}

void write_ply(const std::string& path, const GaussianCloud& cloud) {
    validate(cloud);
    // Extra channels become PLY properties: their names must be single tokens that a reader
    // will not take for one of the 3DGS properties.
    for (std::size_t k = 0; k < cloud.extras.size(); ++k) {
        const std::string& name = cloud.extras[k].name;
        const std::string field = "GaussianCloud.extras['" + name + "']";
        if (name.empty()) throw std::invalid_argument("GaussianCloud.extras[" + std::to_string(k) + "]: empty name");
        for (char ch : name) {
            if (static_cast<unsigned char>(ch) <= ' ' || ch == 127)
                throw std::invalid_argument(field + ": a PLY property name cannot contain spaces or control characters");
        }
        static const char* kReserved[] = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
                                          "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1",
                                          "rot_2", "rot_3", "confidence"};
        bool reserved = starts_with(name, "f_rest_");
        for (const char* r : kReserved) reserved = reserved || name == r;
        if (reserved) throw std::invalid_argument(field + ": the name is a 3DGS PLY property");
        for (std::size_t j = 0; j < k; ++j)
            if (cloud.extras[j].name == name) throw std::invalid_argument(field + ": duplicate extra channel name");
    }

    const std::size_t n = cloud.size();
    const int K = cloud.sh_coeffs();
    const std::size_t rest = 3u * static_cast<std::size_t>(K - 1);
    std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) + "\n";
    for (const char* name : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
        header += std::string("property float ") + name + "\n";
    for (std::size_t k = 0; k < rest; ++k) header += "property float f_rest_" + std::to_string(k) + "\n";
    for (const char* name : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
        header += std::string("property float ") + name + "\n";
    if (cloud.has_confidence()) header += "property float confidence\n";
    for (const auto& e : cloud.extras) header += "property float " + e.name + "\n";
    header += "end_header\n";

    const std::size_t floats = 17 + rest + (cloud.has_confidence() ? 1 : 0) + cloud.extras.size();
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) fail(path, "cannot open for writing");
    out.write(header.data(), static_cast<std::streamsize>(header.size()));

    // Rows are encoded a chunk at a time (in parallel: each row is independent) and written in
    // bulk.
    const std::size_t rows_per_chunk = std::max<std::size_t>(1, (8u << 20) / (4 * floats));
    std::vector<float> buf(std::min(n, rows_per_chunk) * floats);
    for (std::size_t first = 0; first < n; first += rows_per_chunk) {
        const std::size_t rows = std::min(rows_per_chunk, n - first);
        const long long rows_ll = static_cast<long long>(rows);
#pragma omp parallel for schedule(static)
        for (long long k = 0; k < rows_ll; ++k) {
            const std::size_t i = first + static_cast<std::size_t>(k);
            float* o = buf.data() + static_cast<std::size_t>(k) * floats;
            const float* sh = cloud.sh.data() + i * 3 * K;
            *o++ = cloud.means[3 * i + 0];
            *o++ = cloud.means[3 * i + 1];
            *o++ = cloud.means[3 * i + 2];
            *o++ = 0.0f;
            *o++ = 0.0f;
            *o++ = 0.0f;
            *o++ = sh[0];
            *o++ = sh[1];
            *o++ = sh[2];
            for (int c = 0; c < 3; ++c)
                for (int j = 1; j < K; ++j) *o++ = sh[3 * j + c];
            *o++ = encode_opacity(cloud.opacities[i]);
            for (int a = 0; a < 3; ++a) *o++ = encode_scale(cloud.scales[3 * i + a]);
            for (int a = 0; a < 4; ++a) *o++ = cloud.rotations[4 * i + a];
            if (cloud.has_confidence()) *o++ = cloud.confidence[i];
            for (const auto& e : cloud.extras) *o++ = e.values[i];
        }
        if (!kHostLittleEndian) {
            for (std::size_t k = 0; k < rows * floats; ++k) {
                unsigned char b[4];
                std::memcpy(b, &buf[k], 4);
                std::swap(b[0], b[3]);
                std::swap(b[1], b[2]);
                std::memcpy(&buf[k], b, 4);
            }
        }
        out.write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(rows * floats * 4));
        if (!out) fail(path, "write error (disk full?)");
    }
    out.close();
    if (!out) fail(path, "write error while closing the file");
}

}  // namespace avsplat
