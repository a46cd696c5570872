// The generic PLY layer (io/ply_data.h): every element into named columns, and back.
#include "avsplat/io/ply_data.h"

#include "avsplat/io/atomic_file.h"
#include "io/ply/ply_format.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <streambuf>

namespace avsplat {

using ply::fail;

const PlyColumn* PlyElement::find(const std::string& column) const {
    for (const auto& c : columns)
        if (c.name == column) return &c;
    return nullptr;
}

const PlyElement* PlyData::find(const std::string& element) const {
    for (const auto& e : elements)
        if (e.name == element) return &e;
    return nullptr;
}

namespace {

// A read-only, seekable view of a buffer as a stream, so that parsing memory needs no copy.
class MemoryBuf : public std::streambuf {
public:
    MemoryBuf(const unsigned char* data, std::size_t size) {
        char* b = const_cast<char*>(reinterpret_cast<const char*>(data));
        setg(b, b, b + size);
    }

protected:
    pos_type seekoff(off_type off, std::ios_base::seekdir dir, std::ios_base::openmode) override {
        char* target = dir == std::ios_base::beg ? eback() + off
                       : dir == std::ios_base::cur ? gptr() + off
                                                   : egptr() + off;
        if (target < eback() || target > egptr()) return pos_type(off_type(-1));
        setg(eback(), target, egptr());
        return pos_type(target - eback());
    }
    pos_type seekpos(pos_type pos, std::ios_base::openmode mode) override {
        return seekoff(off_type(pos), std::ios_base::beg, mode);
    }
};

std::vector<PlyColumn> empty_columns(const ply::Element& e) {
    std::vector<PlyColumn> cols(e.properties.size());
    for (std::size_t k = 0; k < cols.size(); ++k) {
        cols[k].name = e.properties[k].name;
        cols[k].type = e.properties[k].type;
        cols[k].is_list = e.properties[k].is_list;
        cols[k].count_type = e.properties[k].count_type;
        if (cols[k].is_list) cols[k].offsets.push_back(0);
    }
    return cols;
}

// Binary rows, read one value at a time through the bounded reader: every value read is a byte
// that is in the file, so no count can make this allocate beyond the file's size.
void read_binary_element(ply::BinaryReader& r, const ply::Element& e, bool swap, PlyElement& out) {
    const std::string what = "element \"" + e.name + "\" (" + std::to_string(e.count) + " rows) does not fit in the file";
    if (!e.has_lists()) {
        const std::size_t row = e.row_size();
        if (row != 0 && e.count > r.remaining() / row) fail(r.path(), "truncated file: " + what);
    }
    for (auto& c : out.columns)
        if (!c.is_list) c.values.reserve(static_cast<std::size_t>(e.count));
    unsigned char b[8];
    for (std::uint64_t i = 0; i < e.count; ++i) {
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
            const ply::Property& p = e.properties[k];
            PlyColumn& c = out.columns[k];
            if (!p.is_list) {
                r.read(b, ply::type_size(p.type), what);
                c.values.push_back(ply::load_as_double(b, p.type, swap));
                continue;
            }
            r.read(b, ply::type_size(p.count_type), what);
            const std::uint64_t n = ply::load_count(b, p.count_type, swap);
            const std::size_t item = ply::type_size(p.type);
            if (n > r.remaining() / item) fail(r.path(), "truncated file: " + what);
            for (std::uint64_t j = 0; j < n; ++j) {
                r.read(b, item, what);
                c.values.push_back(ply::load_as_double(b, p.type, swap));
            }
            c.offsets.push_back(c.values.size());
        }
    }
}

void read_ascii_element(ply::LineReader& lines, const ply::Element& e, const std::string& path, PlyElement& out) {
    std::string_view line;
    for (std::uint64_t i = 0; i < e.count; ++i) {
        if (!lines.next(&line))
            fail(path, "truncated file: element \"" + e.name + "\" has " + std::to_string(i) + " of " +
                           std::to_string(e.count) + " rows");
        const auto tok = ply::split_ws(line);
        const std::string where = "element \"" + e.name + "\" row " + std::to_string(i) + " (data line " +
                                  std::to_string(lines.line_no()) + ")";
        std::size_t t = 0;
        auto value = [&](PlyType type, const std::string& prop) {
            if (t >= tok.size()) fail(path, where + " has too few values");
            double v = 0;
            if (!ply::parse_ascii_value(tok[t], type, &v))
                fail(path, where + ": \"" + std::string(tok[t]) + "\" is not a valid value of property \"" + prop + "\"");
            ++t;
            return v;
        };
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
            const ply::Property& p = e.properties[k];
            PlyColumn& c = out.columns[k];
            if (!p.is_list) {
                c.values.push_back(value(p.type, p.name));
                continue;
            }
            const double n = value(p.count_type, p.name);
            if (n < 0 || n > double(tok.size() - t)) fail(path, where + ": list \"" + p.name + "\" has fewer items than its count");
            for (std::uint64_t j = 0; j < static_cast<std::uint64_t>(n); ++j) c.values.push_back(value(p.type, p.name));
            c.offsets.push_back(c.values.size());
        }
        if (t != tok.size())
            fail(path, where + " has " + std::to_string(tok.size()) + " values, more than its properties take");
    }
}

PlyData read_stream(std::istream& in, std::uint64_t size, const std::string& path) {
    if (size == 0) fail(path, "empty file (not a PLY file)");
    const ply::Header h = ply::read_header(in, path);
    PlyData data;
    data.format = h.format;
    data.comments = h.comments;
    const bool swap = (h.format == PlyFormat::BinaryBigEndian) == ply::kHostLittleEndian;
    ply::BinaryReader binary(in, size - h.data_offset, path);
    ply::LineReader lines(in, path);
    for (const ply::Element& e : h.elements) {
        PlyElement out;
        out.name = e.name;
        out.count = e.count;
        out.columns = empty_columns(e);
        if (h.format == PlyFormat::Ascii) read_ascii_element(lines, e, path, out);
        else read_binary_element(binary, e, swap, out);
        data.elements.push_back(std::move(out));
    }
    std::string_view rest;
    if (h.format == PlyFormat::Ascii ? lines.next(&rest) : binary.remaining() != 0)
        fail(path, "data after the last element: the header's counts do not match the data");
    return data;
}

void check_name(const std::string& name, const std::string& what) {
    if (name.empty()) throw std::invalid_argument(what + ": empty name");
    for (char ch : name)
        if (static_cast<unsigned char>(ch) <= ' ' || ch == 127)
            throw std::invalid_argument(what + " \"" + name + "\": a PLY name cannot contain spaces or control characters");
}

// Appends v as type t, little endian; integers must be whole and in range.
void put(std::string& out, PlyType t, double v, const std::string& what) {
    auto integer = [&](double lo, double hi) {
        if (!(v >= lo && v <= hi) || std::floor(v) != v)
            throw std::invalid_argument(what + ": " + std::to_string(v) + " is not a " + ply::type_name(t));
    };
    unsigned char b[8];
    std::size_t n = ply::type_size(t);
    switch (t) {
        case PlyType::Int8: { integer(-128, 127); const std::int8_t x = std::int8_t(v); std::memcpy(b, &x, 1); break; }
        case PlyType::UInt8: { integer(0, 255); const std::uint8_t x = std::uint8_t(v); std::memcpy(b, &x, 1); break; }
        case PlyType::Int16: { integer(-32768, 32767); const std::int16_t x = std::int16_t(v); std::memcpy(b, &x, 2); break; }
        case PlyType::UInt16: { integer(0, 65535); const std::uint16_t x = std::uint16_t(v); std::memcpy(b, &x, 2); break; }
        case PlyType::Int32: { integer(-2147483648.0, 2147483647.0); const std::int32_t x = std::int32_t(v); std::memcpy(b, &x, 4); break; }
        case PlyType::UInt32: { integer(0, 4294967295.0); const std::uint32_t x = std::uint32_t(v); std::memcpy(b, &x, 4); break; }
        case PlyType::Float32: { const float x = float(v); std::memcpy(b, &x, 4); break; }
        case PlyType::Float64: std::memcpy(b, &v, 8); break;
    }
    if (!ply::kHostLittleEndian) std::reverse(b, b + n);
    out.append(reinterpret_cast<const char*>(b), n);
}

}  // namespace

PlyData read_ply_data(const std::string& path) {
    std::ifstream in;
    const std::uint64_t size = ply::open_ply(in, path);
    return read_stream(in, size, path);
}

PlyData parse_ply_data(const unsigned char* data, std::size_t size, const std::string& name) {
    MemoryBuf buf(data, data ? size : 0);
    std::istream in(&buf);
    return read_stream(in, data ? size : 0, name);
}

void write_ply_data(const std::string& path, const PlyData& data) {
    std::string header = "ply\nformat binary_little_endian 1.0\n";
    for (const auto& c : data.comments) {
        if (c.find('\n') != std::string::npos || c.find('\r') != std::string::npos)
            throw std::invalid_argument("PlyData.comments: a comment cannot contain a line break");
        header += "comment " + c + "\n";
    }
    for (const auto& e : data.elements) {
        check_name(e.name, "PlyData element");
        header += "element " + e.name + " " + std::to_string(e.count) + "\n";
        for (const auto& c : e.columns) {
            check_name(c.name, "element \"" + e.name + "\" property");
            const std::string what = "element \"" + e.name + "\" property \"" + c.name + "\"";
            if (c.is_list) {
                if (!ply::is_integer(c.count_type)) throw std::invalid_argument(what + ": list count type must be an integer type");
                if (c.offsets.size() != e.count + 1 || c.offsets.front() != 0 || c.offsets.back() != c.values.size())
                    throw std::invalid_argument(what + ": offsets must have count + 1 entries from 0 to values.size()");
                header += std::string("property list ") + ply::type_name(c.count_type) + " " + ply::type_name(c.type) + " " + c.name + "\n";
            } else {
                if (c.values.size() != e.count)
                    throw std::invalid_argument(what + ": " + std::to_string(c.values.size()) + " values for " +
                                                std::to_string(e.count) + " rows");
                header += std::string("property ") + ply::type_name(c.type) + " " + c.name + "\n";
            }
        }
    }
    header += "end_header\n";
    // Encode everything first: a value that does not fit its type is reported before the file is
    // touched.
    std::string body;
    for (const auto& e : data.elements) {
        for (std::uint64_t i = 0; i < e.count; ++i) {
            for (const auto& c : e.columns) {
                const std::string what = "element \"" + e.name + "\" property \"" + c.name + "\" row " + std::to_string(i);
                if (!c.is_list) {
                    put(body, c.type, c.values[i], what);
                    continue;
                }
                const std::uint64_t a = c.offsets[i], b = c.offsets[i + 1];
                if (b < a) throw std::invalid_argument(what + ": offsets decrease");
                put(body, c.count_type, double(b - a), what + " (list count)");
                for (std::uint64_t j = a; j < b; ++j) put(body, c.type, c.values[j], what);
            }
        }
    }
    AtomicFile out(path);
    out.write(header);
    out.write(body);
    out.commit();
}

}  // namespace avsplat
