// The .npz container (io/npz.h): a zip archive (io/zip_archive.h, libzip) of .npy images
// (io/npy_format.h).
#include "avsplat/io/npz.h"

#include "avsplat/core/error.h"
#include "io/npy_format.h"
#include "io/zip_archive.h"

#include <limits>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

namespace avsplat {

namespace {

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// One ".npy" entry: its header (name, type, shape; no data) and the size of its image.
struct Entry {
    std::size_t index = 0;
    NpyArray header;
    std::uint64_t image_bytes = 0;
};

// The header of entry `index`, from prefixes only (nothing past the .npy header is inflated),
// checked against the size the zip directory declares: the image is then read no further than
// the header says it holds, so a deflate bomb stops at that size.
Entry read_entry_header(const io::ZipReader& zip, std::size_t index, const std::string& what, const std::string& name) {
    const std::uint64_t declared = zip.entries()[index].size;
    Entry e;
    e.index = index;
    std::size_t offset = 0, data = 0;
    try {
        const std::vector<unsigned char> prefix = zip.read_prefix(index, io::kNpyPrefixBytes);
        offset = io::npy_data_offset(prefix.data(), prefix.size(), what);
        const std::vector<unsigned char> head = zip.read_prefix(index, offset);
        e.header = io::npy_header(head.data(), head.size(), what, name);
        data = io::npy_data_size(head.data(), head.size(), what);
    } catch (const IOError&) {
        zip.verify(index);  // corrupt data (a CRC mismatch) is the better explanation, if it is one
        throw;
    }
    if (offset > std::numeric_limits<std::uint64_t>::max() - data || declared > offset + data)
        throw IOError(what + ": the zip directory declares " + std::to_string(declared) +
                      " bytes, more than the " + std::to_string(offset) + " + " + std::to_string(data) +
                      " its .npy header describes (corrupt archive or zip bomb)");
    e.image_bytes = offset + data;
    return e;
}

}  // namespace

std::vector<NpyArray> read_npz(const std::string& path, const NpzHeaderCheck& check) {
    const io::ZipReader zip = io::ZipReader::open_file(path);
    std::vector<Entry> entries;
    std::unordered_set<std::string> names;
    for (std::size_t i = 0; i < zip.entries().size(); ++i) {
        const std::string& entry = zip.entries()[i].name;
        if (!ends_with(entry, ".npy")) continue;
        const std::string what = path + ": entry '" + entry + "'";
        std::string name = entry.substr(0, entry.size() - 4);
        if (!names.insert(name).second) throw IOError(what + ": duplicate array name '" + name + "'");
        entries.push_back(read_entry_header(zip, i, what, name));
    }
    if (check) {
        std::vector<NpyArray> headers;
        headers.reserve(entries.size());
        for (const Entry& e : entries) headers.push_back(e.header);
        check(headers);
    }
    std::vector<NpyArray> arrays;
    arrays.reserve(entries.size());
    for (const Entry& e : entries) {
        const std::string what = path + ": entry '" + zip.entries()[e.index].name + "'";
        const std::vector<unsigned char> image = zip.read(e.index, e.image_bytes);
        arrays.push_back(parse_npy(image.data(), image.size(), what, e.header.name));
    }
    return arrays;
}

std::vector<NpyArray> read_npz(const std::string& path) { return read_npz(path, NpzHeaderCheck()); }

const NpyArray* find_array(const std::vector<NpyArray>& arrays, const std::string& name) {
    for (const auto& a : arrays)
        if (a.name == name) return &a;
    return nullptr;
}

void write_npz(const std::string& path, const std::vector<NpyArray>& arrays, NpzCompression compression) {
    std::unordered_map<std::string, std::size_t> first;
    first.reserve(arrays.size());
    for (std::size_t k = 0; k < arrays.size(); ++k) {
        const NpyArray& a = arrays[k];
        if (a.name.empty() || a.name.size() > 0xfff0 || a.name.find('\0') != std::string::npos)
            throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) +
                                        "].name is empty, too long or contains a NUL byte");
        const auto [it, inserted] = first.emplace(a.name, k);
        if (!inserted)
            throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) + "].name '" + a.name +
                                        "' repeats arrays[" + std::to_string(it->second) + "]");
        if (a.bytes.size() != a.size() * npy_type_size(a.type))
            throw std::invalid_argument("write_npz: arrays[" + std::to_string(k) + "] ('" + a.name + "'): " +
                                        std::to_string(a.bytes.size()) + " bytes do not match shape " +
                                        a.shape_string() + " of " + npy_type_name(a.type));
    }
    std::vector<std::vector<unsigned char>> images;
    images.reserve(arrays.size());
    std::vector<io::ZipWriteEntry> entries;
    entries.reserve(arrays.size());
    for (const NpyArray& a : arrays) {
        images.push_back(io::npy_image(a));
        entries.push_back({a.name + ".npy", images.back().data(), images.back().size(),
                           compression == NpzCompression::Deflated});
    }
    io::write_zip(path, entries);
}

}  // namespace avsplat
