#include "io/ply/ply_format.h"

#include "io/input_file.h"

#include <charconv>
#include <limits>
#include <system_error>
#include <unordered_set>
#include <utility>

namespace avsplat::ply {

bool parse_type(std::string_view s, PlyType* t) {
    static const std::pair<const char*, PlyType> kNames[] = {
        {"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
        {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
        {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
        {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
        {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
        {"float64", PlyType::Float64}};
    for (const auto& [name, type] : kNames) {
        if (s == name) {
            *t = type;
            return true;
        }
    }
    return false;
}

const char* type_name(PlyType t) {
    switch (t) {
        case PlyType::Int8: return "char";
        case PlyType::UInt8: return "uchar";
        case PlyType::Int16: return "short";
        case PlyType::UInt16: return "ushort";
        case PlyType::Int32: return "int";
        case PlyType::UInt32: return "uint";
        case PlyType::Float32: return "float";
        case PlyType::Float64: return "double";
    }
    return "float";
}

std::size_t type_size(PlyType t) {
    switch (t) {
        case PlyType::Int8: case PlyType::UInt8: return 1;
        case PlyType::Int16: case PlyType::UInt16: return 2;
        case PlyType::Int32: case PlyType::UInt32: case PlyType::Float32: return 4;
        case PlyType::Float64: return 8;
    }
    return 0;
}

std::uint64_t open_ply(std::ifstream& in, const std::string& path) {
    const std::uint64_t size = io::regular_file_size(path);
    in.open(path, std::ios::binary);
    if (!in) fail(path, "cannot open for reading");
    if (size == 0) fail(path, "empty file (not a PLY file)");
    return size;
}

static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

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

namespace {

// Longest header line we accept; a real header line is a few dozen characters. Bounding it keeps
// a non-PLY file from being read into memory as one huge "line".
constexpr std::size_t kMaxHeaderLine = 4096;
// Headers are a few kilobytes; this bounds the time spent on a file that never says end_header.
constexpr int kMaxHeaderLines = 100000;

}  // namespace

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
    // Names seen so far (elements; properties of the current element): a set keeps a header of
    // 10^5 properties linear.
    std::unordered_set<std::string> element_names;
    std::unordered_set<std::string> property_names;
    bool ended = false;
    while (!ended) {
        if (line_no >= kMaxHeaderLines) fail(path, "header has no end_header within " + std::to_string(kMaxHeaderLines) + " lines");
        if (!next_line(&line)) fail(path, "header ends before end_header (truncated file?)");
        const std::string where = "header line " + std::to_string(line_no) + " \"" + std::string(line) + "\": ";
        const auto tok = split_ws(line);
        if (tok.empty()) continue;
        const std::string_view key = tok[0];
        if (key == "comment") {
            std::string_view text = line.substr(line.find("comment") + 7);
            if (!text.empty() && is_space(text[0])) text.remove_prefix(1);
            h.comments.emplace_back(text);
            continue;
        }
        if (key == "obj_info") continue;
        if (key == "end_header") {
            if (tok.size() != 1) fail(path, where + "unexpected text after end_header");
            ended = true;
        } else if (key == "format") {
            if (have_format) fail(path, where + "second format line");
            if (!h.elements.empty()) fail(path, where + "format after an element");
            if (tok.size() != 3) fail(path, where + "expected \"format <type> 1.0\"");
            if (tok[1] == "ascii") h.format = PlyFormat::Ascii;
            else if (tok[1] == "binary_little_endian") h.format = PlyFormat::BinaryLittleEndian;
            else if (tok[1] == "binary_big_endian") h.format = PlyFormat::BinaryBigEndian;
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
            if (!element_names.insert(e.name).second) fail(path, where + "duplicate element \"" + e.name + "\"");
            property_names.clear();
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
            if (!property_names.insert(p.name).second) fail(path, where + "duplicate property \"" + p.name + "\"");
            h.elements.back().properties.push_back(std::move(p));
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

double load_as_double(const unsigned char* p, PlyType t, bool swap) {
    switch (t) {
        case PlyType::Int8: return load<std::int8_t>(p, swap);
        case PlyType::UInt8: return load<std::uint8_t>(p, swap);
        case PlyType::Int16: return load<std::int16_t>(p, swap);
        case PlyType::UInt16: return load<std::uint16_t>(p, swap);
        case PlyType::Int32: return load<std::int32_t>(p, swap);
        case PlyType::UInt32: return load<std::uint32_t>(p, swap);
        case PlyType::Float32: return load<float>(p, swap);
        case PlyType::Float64: return load<double>(p, swap);
    }
    return 0.0;
}

// A list count read from a binary file; negative counts are malformed.
std::uint64_t load_count(const unsigned char* p, PlyType t, bool swap) {
    const double v = load_as_double(p, t, swap);
    return v < 0 ? std::numeric_limits<std::uint64_t>::max() : static_cast<std::uint64_t>(v);
}

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

bool parse_ascii_value(std::string_view tok, PlyType t, double* out) {
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
            case PlyType::Int8: lo = INT8_MIN; hi = INT8_MAX; break;
            case PlyType::UInt8: lo = 0; hi = UINT8_MAX; break;
            case PlyType::Int16: lo = INT16_MIN; hi = INT16_MAX; break;
            case PlyType::UInt16: lo = 0; hi = UINT16_MAX; break;
            case PlyType::Int32: lo = INT32_MIN; hi = INT32_MAX; break;
            default: lo = 0; hi = UINT32_MAX; break;
        }
        if (v < lo || v > hi) return false;
        *out = static_cast<double>(v);
        return true;
    }
    // Parse float properties as float so that a decimal float32 reads back to the same bits
    // (decimal -> double -> float can round twice).
    if (t == PlyType::Float32) {
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

}  // namespace avsplat::ply
