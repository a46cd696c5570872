// The .npy array format (io/npz.h, io/npy_format.h): parsing, element conversion and the image
// write_npz stores. The header follows numpy's format.py (NEP 1). The .npz container is npz.cpp.
#include "io/npy_format.h"

#include "avsplat/core/error.h"
#include "io/input_file.h"

#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <stdexcept>
#include <type_traits>

namespace avsplat {

namespace {

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
constexpr bool kHostLittleEndian = false;
#else
constexpr bool kHostLittleEndian = true;
#endif

struct TypeInfo {
    NpyType type;
    char kind;  // numpy's kind character: b (bool), i, u, f
    std::size_t size;
    const char* name;
};

constexpr TypeInfo kTypes[] = {
    {NpyType::Bool, 'b', 1, "bool"},       {NpyType::Int8, 'i', 1, "int8"},
    {NpyType::Int16, 'i', 2, "int16"},     {NpyType::Int32, 'i', 4, "int32"},
    {NpyType::Int64, 'i', 8, "int64"},     {NpyType::UInt8, 'u', 1, "uint8"},
    {NpyType::UInt16, 'u', 2, "uint16"},   {NpyType::UInt32, 'u', 4, "uint32"},
    {NpyType::UInt64, 'u', 8, "uint64"},   {NpyType::Float16, 'f', 2, "float16"},
    {NpyType::Float32, 'f', 4, "float32"}, {NpyType::Float64, 'f', 8, "float64"},
};

const TypeInfo& info(NpyType type) {
    for (const auto& t : kTypes)
        if (t.type == type) return t;
    throw std::invalid_argument("NpyType: unknown value " + std::to_string(static_cast<int>(type)));
}

// ---------------------------------------------------------------------------------------------
// Little-endian field access on byte buffers whose bounds the caller has checked.

std::uint16_t le16(const unsigned char* p) { return std::uint16_t(p[0] | (p[1] << 8)); }
std::uint32_t le32(const unsigned char* p) {
    return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) |
           (std::uint32_t(p[3]) << 24);
}

void put16(std::vector<unsigned char>& out, std::uint32_t v) {
    out.push_back(static_cast<unsigned char>(v & 0xff));
    out.push_back(static_cast<unsigned char>((v >> 8) & 0xff));
}
void put32(std::vector<unsigned char>& out, std::uint32_t v) {
    put16(out, v & 0xffff);
    put16(out, v >> 16);
}

// ---------------------------------------------------------------------------------------------
// Element conversion.

// float16 -> float32 is exact; Eigen's half does the bit work (NaN payloads, subnormals).
float half_to_float(std::uint16_t h) {
    return static_cast<float>(Eigen::half(Eigen::half_impl::raw_uint16_to_half(h)));
}

template <class T>
T load(const unsigned char* p) {
    T v;
    std::memcpy(&v, p, sizeof(T));
    return v;
}

// Calls f(double-or-exact value) for every element; Out is float or double.
template <class Out>
std::vector<Out> convert(const NpyArray& a) {
    const std::size_t n = a.size();
    if (a.bytes.size() != n * npy_type_size(a.type))
        throw std::invalid_argument("NpyArray '" + a.name + "': " + std::to_string(a.bytes.size()) +
                                    " bytes do not match shape " + a.shape_string() + " of " +
                                    npy_type_name(a.type));
    std::vector<Out> out(n);
    const unsigned char* p = a.bytes.data();
    auto each = [&](auto tag) {
        using T = decltype(tag);
        for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<Out>(load<T>(p + i * sizeof(T)));
    };
    switch (a.type) {
        case NpyType::Bool:
            for (std::size_t i = 0; i < n; ++i) out[i] = p[i] != 0 ? Out(1) : Out(0);
            break;
        case NpyType::Int8: each(std::int8_t{}); break;
        case NpyType::Int16: each(std::int16_t{}); break;
        case NpyType::Int32: each(std::int32_t{}); break;
        case NpyType::Int64: each(std::int64_t{}); break;
        case NpyType::UInt8: each(std::uint8_t{}); break;
        case NpyType::UInt16: each(std::uint16_t{}); break;
        case NpyType::UInt32: each(std::uint32_t{}); break;
        case NpyType::UInt64: each(std::uint64_t{}); break;
        case NpyType::Float16:
            for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<Out>(half_to_float(load<std::uint16_t>(p + 2 * i)));
            break;
        case NpyType::Float32: each(float{}); break;
        case NpyType::Float64: each(double{}); break;
    }
    return out;
}

void byteswap_elements(std::vector<unsigned char>& bytes, std::size_t element_size) {
    if (element_size < 2) return;
    for (std::size_t i = 0; i + element_size <= bytes.size(); i += element_size)
        std::reverse(bytes.begin() + static_cast<std::ptrdiff_t>(i),
                     bytes.begin() + static_cast<std::ptrdiff_t>(i + element_size));
}

// ---------------------------------------------------------------------------------------------
// The .npy header: a Python dict literal {'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }

struct NpyHeader {
    std::string descr;
    bool fortran_order = false;
    std::vector<std::size_t> shape;
};

class HeaderParser {
public:
    HeaderParser(const std::string& text, const std::string& what) : s_(text), what_(what) {}

    NpyHeader parse() {
        NpyHeader h;
        bool have_descr = false, have_order = false, have_shape = false;
        expect('{');
        for (;;) {
            skip_space();
            if (peek() == '}') { ++i_; break; }
            const std::string key = parse_string();
            expect(':');
            skip_space();
            if (key == "descr") {
                if (peek() == '[') fail("structured dtypes (a list 'descr') are not supported");
                h.descr = parse_string();
                have_descr = true;
            } else if (key == "fortran_order") {
                h.fortran_order = parse_bool();
                have_order = true;
            } else if (key == "shape") {
                h.shape = parse_shape();
                have_shape = true;
            } else {
                fail("unexpected key '" + key + "'");
            }
            skip_space();
            if (peek() == ',') { ++i_; continue; }
            skip_space();
            if (peek() == '}') { ++i_; break; }
            fail("expected ',' or '}' in the dictionary");
        }
        skip_space();
        if (i_ != s_.size()) fail("unexpected text after the dictionary");
        if (!have_descr || !have_order || !have_shape)
            fail(std::string("missing key '") + (!have_descr ? "descr" : !have_order ? "fortran_order" : "shape") + "'");
        return h;
    }

private:
    [[noreturn]] void fail(const std::string& why) const {
        throw IOError(what_ + ": invalid .npy header (" + why + ")");
    }
    char peek() const { return i_ < s_.size() ? s_[i_] : '\0'; }
    void skip_space() {
        while (i_ < s_.size() && (s_[i_] == ' ' || s_[i_] == '\n' || s_[i_] == '\t' || s_[i_] == '\r')) ++i_;
    }
    void expect(char c) {
        skip_space();
        if (peek() != c) fail(std::string("expected '") + c + "'");
        ++i_;
    }
    std::string parse_string() {
        skip_space();
        const char quote = peek();
        if (quote != '\'' && quote != '"') fail("expected a quoted string");
        const std::size_t end = s_.find(quote, i_ + 1);
        if (end == std::string::npos) fail("unterminated string");
        std::string out = s_.substr(i_ + 1, end - i_ - 1);
        i_ = end + 1;
        return out;
    }
    bool parse_bool() {
        if (s_.compare(i_, 4, "True") == 0) { i_ += 4; return true; }
        if (s_.compare(i_, 5, "False") == 0) { i_ += 5; return false; }
        fail("fortran_order is neither True nor False");
    }
    std::vector<std::size_t> parse_shape() {
        if (peek() != '(') fail("shape is not a tuple");
        ++i_;
        std::vector<std::size_t> shape;
        for (;;) {
            skip_space();
            if (peek() == ')') { ++i_; break; }
            if (!(peek() >= '0' && peek() <= '9')) fail("shape entry is not a non-negative integer");
            std::size_t v = 0;
            while (peek() >= '0' && peek() <= '9') {
                const std::size_t digit = static_cast<std::size_t>(peek() - '0');
                if (v > (std::numeric_limits<std::size_t>::max() - digit) / 10) fail("shape entry too large");
                v = v * 10 + digit;
                ++i_;
            }
            if (peek() == 'L') ++i_;  // Python 2 long literal, written by old numpy versions
            shape.push_back(v);
            skip_space();
            if (peek() == ',') { ++i_; continue; }
            skip_space();
            if (peek() == ')') { ++i_; break; }
            fail("expected ',' or ')' in the shape");
        }
        return shape;
    }

    const std::string& s_;
    const std::string& what_;
    std::size_t i_ = 0;
};

// Element type and whether the data is little endian, from a descr such as "<f4" or "|b1".
std::pair<NpyType, bool> parse_descr(const std::string& descr, const std::string& what) {
    auto bad = [&](const std::string& why) {
        return IOError(what + ": dtype '" + descr + "' " + why +
                       " (supported: bool, int8..int64, uint8..uint64, float16, float32, float64)");
    };
    if (descr.size() < 2) throw bad("is not understood");
    const char order = descr[0];
    if (order != '<' && order != '>' && order != '|' && order != '=') throw bad("is not understood");
    const char kind = descr[1];
    if (kind == 'O') throw bad("holds Python objects (pickled), which are not supported");
    std::size_t size = 0;
    std::size_t k = 2;
    for (; k < descr.size() && descr[k] >= '0' && descr[k] <= '9' && size < 64; ++k)
        size = size * 10 + static_cast<std::size_t>(descr[k] - '0');
    if (k != descr.size() || k == 2) throw bad("is not supported");
    for (const auto& t : kTypes)
        if (t.kind == kind && t.size == size) {
            const bool little = order == '<' || order == '|' || (order == '=' && kHostLittleEndian);
            return {t.type, little};
        }
    throw bad("is not supported");
}

// Product of the shape and the byte count, or an IOError when they overflow size_t.
std::size_t checked_bytes(const std::vector<std::size_t>& shape, std::size_t element_size,
                          const std::string& what) {
    std::size_t n = element_size;
    for (std::size_t d : shape) {
        if (d != 0 && n > std::numeric_limits<std::size_t>::max() / d)
            throw IOError(what + ": shape too large");
        n *= d;
    }
    return n;
}

// Reorders Fortran-order elements into C order.
std::vector<unsigned char> fortran_to_c(const std::vector<unsigned char>& in,
                                        const std::vector<std::size_t>& shape, std::size_t element_size) {
    std::vector<unsigned char> out(in.size());
    const std::size_t rank = shape.size();
    std::size_t count = 1;
    for (std::size_t d : shape) count *= d;
    if (count == 0 || rank < 2) return in;
    std::vector<std::size_t> stride(rank, 1);  // Fortran strides in elements
    for (std::size_t k = 1; k < rank; ++k) stride[k] = stride[k - 1] * shape[k - 1];
    std::vector<std::size_t> index(rank, 0);
    std::size_t source = 0;
    for (std::size_t c = 0; c < count; ++c) {
        std::memcpy(&out[c * element_size], &in[source * element_size], element_size);
        // Advance the C-order index (last axis fastest), keeping the Fortran offset in step.
        for (std::size_t k = rank; k-- > 0;) {
            if (++index[k] < shape[k]) { source += stride[k]; break; }
            source -= stride[k] * (shape[k] - 1);
            index[k] = 0;
        }
    }
    return out;
}

template <class T> constexpr NpyType type_of();
template <> constexpr NpyType type_of<bool>() { return NpyType::Bool; }
template <> constexpr NpyType type_of<std::int8_t>() { return NpyType::Int8; }
template <> constexpr NpyType type_of<std::int16_t>() { return NpyType::Int16; }
template <> constexpr NpyType type_of<std::int32_t>() { return NpyType::Int32; }
template <> constexpr NpyType type_of<std::int64_t>() { return NpyType::Int64; }
template <> constexpr NpyType type_of<std::uint8_t>() { return NpyType::UInt8; }
template <> constexpr NpyType type_of<std::uint16_t>() { return NpyType::UInt16; }
template <> constexpr NpyType type_of<std::uint32_t>() { return NpyType::UInt32; }
template <> constexpr NpyType type_of<std::uint64_t>() { return NpyType::UInt64; }
template <> constexpr NpyType type_of<float>() { return NpyType::Float32; }
template <> constexpr NpyType type_of<double>() { return NpyType::Float64; }

}  // namespace

// -------------------------------------------------------------------------------------------------

std::size_t npy_type_size(NpyType type) { return info(type).size; }

const char* npy_type_name(NpyType type) { return info(type).name; }

std::size_t NpyArray::size() const {
    std::size_t n = 1;
    for (std::size_t d : shape) n *= d;
    return n;
}

std::string NpyArray::shape_string() const {
    std::string s = "(";
    for (std::size_t k = 0; k < shape.size(); ++k) s += (k ? ", " : "") + std::to_string(shape[k]);
    return s + (shape.size() == 1 ? ",)" : ")");
}

std::vector<float> NpyArray::to_float32() const { return convert<float>(*this); }

std::vector<double> NpyArray::to_float64() const { return convert<double>(*this); }

template <class T>
NpyArray NpyArray::from_data(std::string name, std::vector<std::size_t> shape, const T* data) {
    NpyArray a;
    a.name = std::move(name);
    a.type = type_of<T>();
    a.shape = std::move(shape);
    const std::size_t n = a.size();
    if (n > 0 && data == nullptr)
        throw std::invalid_argument("NpyArray::from_data('" + a.name + "'): data is null for shape " + a.shape_string());
    a.bytes.resize(n * sizeof(T));
    if (n > 0) {
        if constexpr (std::is_same_v<T, bool>) {
            for (std::size_t i = 0; i < n; ++i) a.bytes[i] = data[i] ? 1 : 0;
        } else {
            std::memcpy(a.bytes.data(), data, a.bytes.size());
        }
    }
    return a;
}

template NpyArray NpyArray::from_data<bool>(std::string, std::vector<std::size_t>, const bool*);
template NpyArray NpyArray::from_data<std::int8_t>(std::string, std::vector<std::size_t>, const std::int8_t*);
template NpyArray NpyArray::from_data<std::int16_t>(std::string, std::vector<std::size_t>, const std::int16_t*);
template NpyArray NpyArray::from_data<std::int32_t>(std::string, std::vector<std::size_t>, const std::int32_t*);
template NpyArray NpyArray::from_data<std::int64_t>(std::string, std::vector<std::size_t>, const std::int64_t*);
template NpyArray NpyArray::from_data<std::uint8_t>(std::string, std::vector<std::size_t>, const std::uint8_t*);
template NpyArray NpyArray::from_data<std::uint16_t>(std::string, std::vector<std::size_t>, const std::uint16_t*);
template NpyArray NpyArray::from_data<std::uint32_t>(std::string, std::vector<std::size_t>, const std::uint32_t*);
template NpyArray NpyArray::from_data<std::uint64_t>(std::string, std::vector<std::size_t>, const std::uint64_t*);
template NpyArray NpyArray::from_data<float>(std::string, std::vector<std::size_t>, const float*);
template NpyArray NpyArray::from_data<double>(std::string, std::vector<std::size_t>, const double*);

namespace io {

std::size_t npy_data_offset(const unsigned char* data, std::size_t size, const std::string& what) {
    static const unsigned char kMagic[6] = {0x93, 'N', 'U', 'M', 'P', 'Y'};
    if (size < 10 || std::memcmp(data, kMagic, 6) != 0) throw IOError(what + ": not a .npy array (bad magic)");
    const unsigned major = data[6];
    if (major < 1 || major > 3)
        throw IOError(what + ": .npy format version " + std::to_string(major) + "." +
                      std::to_string(data[7]) + " is not supported (1.0, 2.0, 3.0)");
    const std::size_t prefix = major == 1 ? 10 : 12;
    if (size < prefix) throw IOError(what + ": truncated .npy header");
    const std::size_t header_len = major == 1 ? le16(data + 8) : le32(data + 8);
    if (header_len > kNpyMaxHeader)
        throw IOError(what + ": .npy header of " + std::to_string(header_len) + " bytes is larger than the " +
                      std::to_string(kNpyMaxHeader) + " this reader accepts (corrupt file)");
    return prefix + header_len;
}

namespace {

struct Layout {
    NpyHeader header;
    NpyType type;
    bool little;
    std::size_t offset, bytes;
};

Layout layout(const unsigned char* data, std::size_t size, const std::string& what) {
    const std::size_t offset = npy_data_offset(data, size, what);
    if (offset > size) throw IOError(what + ": truncated .npy header");
    const std::size_t prefix = data[6] == 1 ? 10 : 12;
    // Version 3 allows UTF-8 in the header; the keys and values we accept are ASCII either way.
    const std::string text(reinterpret_cast<const char*>(data + prefix), offset - prefix);
    Layout l{HeaderParser(text, what).parse(), NpyType::Float32, true, offset, 0};
    std::tie(l.type, l.little) = parse_descr(l.header.descr, what);
    l.bytes = checked_bytes(l.header.shape, npy_type_size(l.type), what);
    return l;
}

}  // namespace

std::size_t npy_data_size(const unsigned char* data, std::size_t size, const std::string& what) {
    return layout(data, size, what).bytes;
}

NpyArray npy_header(const unsigned char* data, std::size_t size, const std::string& what, const std::string& name) {
    const Layout l = layout(data, size, what);
    NpyArray a;
    a.name = name;
    a.type = l.type;
    a.shape = l.header.shape;
    return a;
}

}  // namespace io

NpyArray parse_npy(const unsigned char* data, std::size_t size, const std::string& what,
                   const std::string& name) {
    const io::Layout l = io::layout(data, size, what);
    NpyArray a;
    a.name = name;
    a.type = l.type;
    a.shape = l.header.shape;
    const std::size_t available = size - l.offset;
    if (available != l.bytes)
        throw IOError(what + ": data has " + std::to_string(available) + " bytes, shape " +
                      a.shape_string() + " of " + npy_type_name(l.type) + " needs " +
                      std::to_string(l.bytes) + " (truncated or corrupt)");
    const unsigned char* body = data + l.offset;
    a.bytes.assign(body, body + l.bytes);
    const std::size_t element = npy_type_size(l.type);
    if (l.little != kHostLittleEndian) byteswap_elements(a.bytes, element);
    if (l.header.fortran_order) a.bytes = fortran_to_c(a.bytes, a.shape, element);
    return a;
}

NpyArray read_npy(const std::string& path) {
    const std::uint64_t size = io::regular_file_size(path);
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading");
    std::vector<unsigned char> image(static_cast<std::size_t>(size));
    if (size > 0 && !in.read(reinterpret_cast<char*>(image.data()), static_cast<std::streamsize>(size)))
        throw IOError(path + ": read failed (the file shrank or cannot be read)");
    std::string name = path.substr(path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1);
    if (name.size() >= 4 && name.compare(name.size() - 4, 4, ".npy") == 0) name.resize(name.size() - 4);
    return parse_npy(image.data(), image.size(), path, name);
}

namespace io {

std::vector<unsigned char> npy_image(const NpyArray& a) {
    const TypeInfo& t = info(a.type);
    std::string dict = std::string("{'descr': '") + (t.size == 1 ? '|' : '<') + t.kind +
                       std::to_string(t.size) + "', 'fortran_order': False, 'shape': (";
    for (std::size_t k = 0; k < a.shape.size(); ++k) dict += (k ? ", " : "") + std::to_string(a.shape[k]);
    dict += a.shape.size() == 1 ? ",), }" : "), }";
    // numpy pads the header with spaces and a newline so that the data starts at a multiple of 64.
    const bool v2 = dict.size() + 11 + 64 > 0xffff;
    const std::size_t prefix = v2 ? 12 : 10;
    const std::size_t total = (prefix + dict.size() + 1 + 63) / 64 * 64;
    dict.append(total - prefix - dict.size() - 1, ' ');
    dict += '\n';
    std::vector<unsigned char> out = {0x93, 'N', 'U', 'M', 'P', 'Y', static_cast<unsigned char>(v2 ? 2 : 1), 0};
    if (v2) put32(out, static_cast<std::uint32_t>(dict.size()));
    else put16(out, static_cast<std::uint32_t>(dict.size()));
    out.insert(out.end(), dict.begin(), dict.end());
    const std::size_t data_pos = out.size();
    out.insert(out.end(), a.bytes.begin(), a.bytes.end());
    if (!kHostLittleEndian) {
        std::vector<unsigned char> data(out.begin() + static_cast<std::ptrdiff_t>(data_pos), out.end());
        byteswap_elements(data, t.size);
        std::copy(data.begin(), data.end(), out.begin() + static_cast<std::ptrdiff_t>(data_pos));
    }
    return out;
}

}  // namespace io

}  // namespace avsplat
