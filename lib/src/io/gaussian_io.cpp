// Format dispatch for Gaussians: one table, one entry per format (io/gaussian_io.h).
#include "avsplat/io/gaussian_io.h"

#include "avsplat/core/error.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/glb.h"
#include "avsplat/io/ksplat.h"
#include "avsplat/io/lod_set.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/sog.h"
#include "avsplat/io/splat.h"
#include "avsplat/io/spz.h"
#include "io/input_file.h"
#include "io/ply/ply_format.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <vector>

namespace avsplat {

namespace {

using Reader = GaussianCloud (*)(const std::string&);
using Writer = void (*)(const std::string&, const GaussianCloud&);

struct FormatEntry {
    GaussianFormat format;
    const char* name;
    const char* suffix;  // write_gaussians chooses the format for names ending so
    Reader read;         // nullptr: not in this build
    Writer write;
};

// One entry per format. The longest matching suffix wins when writing.
const FormatEntry kFormats[] = {
    {GaussianFormat::Ply, "3DGS PLY", ".ply", read_ply, write_ply},
    {GaussianFormat::CompressedPly, "compressed PLY", ".compressed.ply", read_compressed_ply,
     [](const std::string& p, const GaussianCloud& c) { write_compressed_ply(p, c); }},
    {GaussianFormat::Splat, ".splat", ".splat", read_splat, write_splat},
    {GaussianFormat::Spz, "SPZ", ".spz", [](const std::string& p) { return read_spz(p); },
     [](const std::string& p, const GaussianCloud& c) { write_spz(p, c); }},
    {GaussianFormat::Sog, "SOG", ".sog", [](const std::string& p) { return read_sog(p); },
     [](const std::string& p, const GaussianCloud& c) { write_sog(p, c); }},
    {GaussianFormat::Glb, "glTF binary", ".glb", [](const std::string& p) { return read_glb(p); },
     [](const std::string& p, const GaussianCloud& c) { write_glb(p, c); }},
    // Read only; listed so that names ending in .ksplat are not taken for .splat when writing.
    {GaussianFormat::Ksplat, ".ksplat", ".ksplat", read_ksplat, nullptr},
    // A LOD set reads as its finest level (as splat-transform converts one without -L); a cloud
    // is written as a set of that one level. Levels: io/lod_set.h.
    {GaussianFormat::LodSet, "LOD set", "lod-meta.json",
     [](const std::string& p) { return std::move(read_lod_set(p, {0})[0]); },
     [](const std::string& p, const GaussianCloud& c) { write_lod_set(p, {c}); }},
};

const FormatEntry& entry(GaussianFormat f) {
    for (const auto& e : kFormats)
        if (e.format == f) return e;
    throw std::logic_error("gaussian_io: a GaussianFormat without a table entry");
}

std::string lower(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char ch) { return std::tolower(ch); });
    return s;
}

bool ends_with(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string base_name(const std::string& path) {
    const auto slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

GaussianFormatInfo info(GaussianFormat f, std::string version) {
    return {f, entry(f).name, std::move(version)};
}

GaussianFormatInfo detect_ply(const std::string& path) {
    std::ifstream in;
    ply::open_ply(in, path);
    const ply::Header h = ply::read_header(in, path);
    const char* encoding = h.format == PlyFormat::Ascii ? "ascii" : h.format == PlyFormat::BinaryLittleEndian
                                                                        ? "binary_little_endian"
                                                                        : "binary_big_endian";
    for (const auto& e : h.elements) {
        if (e.name != "vertex") continue;
        for (const auto& p : e.properties) {
            if (p.name != "packed_position") continue;
            // Version 1 had no colour bounds in its chunk element; version 2 added min_r .. max_b.
            bool colour = false;
            for (const auto& c : h.elements)
                if (c.name == "chunk")
                    for (const auto& q : c.properties) colour = colour || q.name == "min_r";
            return info(GaussianFormat::CompressedPly, colour ? "2 (chunk colour bounds)" : "1 (no chunk colour bounds)");
        }
    }
    return info(GaussianFormat::Ply, std::string(encoding) + " 1.0");
}

}  // namespace

std::string file_extension(const std::string& path) {
    const auto slash = path.find_last_of("/\\");
    const auto dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
    return lower(path.substr(dot));
}

const char* gaussian_format_name(GaussianFormat format) { return entry(format).name; }
bool can_read_gaussian_format(GaussianFormat format) { return entry(format).read != nullptr; }
bool can_write_gaussian_format(GaussianFormat format) { return entry(format).write != nullptr; }

// .splat has no signature, so a file of another kind whose size is a multiple of 32 bytes is
// only taken for one when its content looks like .splat: not text (the first bytes are not all
// printable ASCII, as JSON, CSV or OBJ are), and every record among the first kProbeRecords has
// finite positions within +-1e9, finite scales in [0, 1e9] and a non-zero quaternion.
bool looks_like_splat(const std::string& path, std::uint64_t size) {
    constexpr std::size_t kProbeRecords = 256, kRecord = 32;
    std::vector<unsigned char> bytes(static_cast<std::size_t>(std::min<std::uint64_t>(size, kProbeRecords * kRecord)));
    std::ifstream in(path, std::ios::binary);
    if (!in || !in.read(reinterpret_cast<char*>(bytes.data()), static_cast<std::streamsize>(bytes.size())))
        return false;
    const std::size_t text_probe = std::min<std::size_t>(bytes.size(), 512);
    bool text = true;
    for (std::size_t i = 0; text && i < text_probe; ++i)
        text = (bytes[i] >= 0x20 && bytes[i] < 0x7f) || bytes[i] == '\n' || bytes[i] == '\r' || bytes[i] == '\t';
    if (text) return false;
    for (std::size_t r = 0; r + kRecord <= bytes.size(); r += kRecord) {
        float v[6];
        std::memcpy(v, &bytes[r], sizeof v);
        for (int k = 0; k < 6; ++k)
            if (!(k < 3 ? std::fabs(v[k]) <= 1e9f : v[k] >= 0.f && v[k] <= 1e9f)) return false;
        if (bytes[r + 28] == 128 && bytes[r + 29] == 128 && bytes[r + 30] == 128 && bytes[r + 31] == 128) return false;
    }
    return true;
}

GaussianFormatInfo detect_gaussian_format(const std::string& path) {
    if (path.find('\0') != std::string::npos) throw IOError(path + ": cannot open for reading: the path contains a NUL byte");
    struct stat st;
    if (::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
        // SOG unbundled: a folder holding meta.json and its images.
        struct stat meta;
        if (::stat((path + "/meta.json").c_str(), &meta) == 0 && S_ISREG(meta.st_mode)) return info(GaussianFormat::Sog, "");
    }
    const std::uint64_t size = io::regular_file_size(path);
    unsigned char head[8] = {0};
    std::size_t got = 0;
    {
        std::ifstream in(path, std::ios::binary);
        if (!in) throw IOError(path + ": cannot open for reading");
        in.read(reinterpret_cast<char*>(head), sizeof head);
        got = static_cast<std::size_t>(in.gcount());
    }
    if (got >= 4 && std::memcmp(head, "ply", 3) == 0 && (head[3] == '\n' || head[3] == '\r')) return detect_ply(path);
    // SPZ 1..3 is one gzip stream, 4 starts with "NGSP". The version is the header's when it can be
    // read; a damaged header is the reader's to report, with its field.
    if ((got >= 2 && head[0] == 0x1f && head[1] == 0x8b) || (got >= 4 && std::memcmp(head, "NGSP", 4) == 0)) {
        std::string version;
        try {
            version = std::to_string(read_spz_header(path).version);
        } catch (const IOError&) {
        }
        return info(GaussianFormat::Spz, version);
    }
    if (got >= 4 && std::memcmp(head, "PK\x03\x04", 4) == 0) return info(GaussianFormat::Sog, "");
    if (is_glb(head, got)) return info(GaussianFormat::Glb, got >= 8 ? std::to_string(head[4] | head[5] << 8) : "");
    if (lower(base_name(path)) == "meta.json") return info(GaussianFormat::Sog, "");
    if (file_extension(path) == ".json" && is_lod_set(path)) return info(GaussianFormat::LodSet, "");
    const std::string ext = file_extension(path);
    if (ext == ".ksplat" || is_ksplat_file(path)) return info(GaussianFormat::Ksplat, "");
    // .splat has no signature: the name says so, or (renamed files) the size fits its records.
    // A name that claims a format with a signature is not guessed at: it is a damaged file.
    if (ext == ".splat") return info(GaussianFormat::Splat, "");
    if (ext == ".ply") throw IOError(path + ": not a PLY file: it does not start with \"ply\"");
    if (ext == ".spz" || ext == ".sog" || ext == ".glb")
        throw IOError(path + ": not a " + entry(gaussian_format_for_name(path)).name +
                      " file: it does not start with the format's signature");
    if (size > 0 && size % 32 == 0 && looks_like_splat(path, size)) return info(GaussianFormat::Splat, "");
    const std::string why =
        size == 0        ? std::string("the file is empty")
        : size % 32 == 0 ? "no known signature, and its first 32-byte records are not .splat records (text, or "
                           "positions and scales that are not finite and plausible); name it .splat to read it as one"
                         : "no known signature and the size " + std::to_string(size) +
                               " is not a multiple of the 32-byte .splat record";
    throw IOError(path + ": not a Gaussian file this library knows (3DGS PLY, compressed PLY, .splat, SPZ, SOG, LOD set, .glb, .ksplat): " +
                  why);
}

GaussianFormat gaussian_format_for_name(const std::string& path) {
    const std::string name = lower(base_name(path));
    const FormatEntry* best = nullptr;
    for (const auto& e : kFormats)
        if (ends_with(name, e.suffix) && (!best || std::strlen(e.suffix) > std::strlen(best->suffix))) best = &e;
    if (!best) {
        std::string list;
        for (const auto& e : kFormats) list += std::string(list.empty() ? "" : ", ") + e.suffix;
        throw IOError(path + ": unsupported extension '" + file_extension(path) + "' for Gaussians (" + list + ")");
    }
    return best->format;
}

GaussianCloud read_gaussians(const std::string& path) {
    const GaussianFormatInfo f = detect_gaussian_format(path);
    const FormatEntry& e = entry(f.format);
    if (!e.read) throw IOError(path + ": " + e.name + " files cannot be read by this build of avsplat");
    return e.read(path);
}

void write_gaussians(const std::string& path, const GaussianCloud& cloud) {
    const FormatEntry& e = entry(gaussian_format_for_name(path));
    if (!e.write) throw IOError(path + ": " + e.name + " files cannot be written by this build of avsplat");
    e.write(path, cloud);
}

}  // namespace avsplat
