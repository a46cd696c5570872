// Private: the PLY parsing primitives shared by the generic column layer (ply_data.cpp) and the
// 3DGS mapping (gaussian_ply.cpp): the header model and its parser, binary loads and skips, and
// the ASCII line reader. Every failure throws avsplat::IOError "<path>: <problem>".
#pragma once

#include "avsplat/core/error.h"
#include "avsplat/io/ply_data.h"

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <istream>
#include <string>
#include <string_view>
#include <vector>

namespace avsplat::ply {

[[noreturn]] inline void fail(const std::string& path, const std::string& what) {
    throw IOError(path + ": " + what);
}

// ---------------------------------------------------------------------------------------------
// Header model.

/// Parses a PLY type name (char uchar short ushort int uint float double and the int8.. names).
bool parse_type(std::string_view s, PlyType* t);
/// The PLY name of a type, as written: "char", "uchar", ..., "float", "double".
const char* type_name(PlyType t);
std::size_t type_size(PlyType t);
inline bool is_integer(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

struct Property {
    std::string name;
    PlyType type = PlyType::Float32;
    bool is_list = false;
    PlyType count_type = PlyType::UInt8;  // lists only
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
    PlyFormat format = PlyFormat::Ascii;
    std::vector<std::string> comments;
    std::vector<Element> elements;
    std::uint64_t data_offset = 0;  // first byte after "end_header\n"
};

/// Opens the PLY file at `path` for binary reading and returns its size; throws IOError when it
/// is not a regular file, cannot be opened or is empty.
std::uint64_t open_ply(std::ifstream& in, const std::string& path);

/// The whitespace-separated tokens of a line.
std::vector<std::string_view> split_ws(std::string_view line);

/// Reads the header from the start of `in`; on return `in` is at the first data byte, and
/// data_offset says where that is. Linear in the header's size.
Header read_header(std::istream& in, const std::string& path);

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

double load_as_double(const unsigned char* p, PlyType t, bool swap);

/// A list count read from a binary file; a negative count becomes UINT64_MAX (malformed).
std::uint64_t load_count(const unsigned char* p, PlyType t, bool swap);

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

/// Skips one element's rows (lists included) in a binary file.
void skip_binary_element(BinaryReader& r, const Element& e, bool swap);

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

/// Parses one ASCII token as a value of type t (range-checked integers; float32 parsed as float
/// so that a written float reads back to the same bits).
bool parse_ascii_value(std::string_view tok, PlyType t, double* out);

}  // namespace avsplat::ply
