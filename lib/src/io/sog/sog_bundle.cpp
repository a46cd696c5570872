// The two forms of a SOG on disk: a `.sog` zip archive (through io/zip_archive.h) and a folder of
// meta.json and images. Both become the in-memory SogFiles that sog_codec.cpp decodes.
#include "avsplat/io/sog.h"

#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "io/input_file.h"
#include "io/sog/sog_meta.h"
#include "io/zip_archive.h"

#include <nlohmann/json.hpp>
#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <fstream>

namespace avsplat {

namespace {

// Largest image file read: a lossless WebP is at most a little over 4 bytes per texel, and the
// reader allows 2 * count + 2^22 texels per image.
std::uint64_t max_image_bytes(std::size_t count) {
    return 1024 + 8 * (2 * std::uint64_t(count) + (std::uint64_t(1) << 22));
}

bool is_zip(const std::string& head) { return head.size() >= 4 && head.compare(0, 4, "PK\x03\x04", 4) == 0; }

std::string parent(const std::string& path) {
    const auto slash = path.find_last_of('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

std::string read_bounded(const std::string& path, std::uint64_t max_bytes, const std::string& field) {
    const std::uint64_t size = io::regular_file_size(path);
    if (size > max_bytes)
        throw IOError(path + ": " + std::to_string(size) + " bytes, more than the " + std::to_string(max_bytes) +
                      " a SOG " + field + " may have");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
    std::string bytes(static_cast<std::size_t>(size), '\0');
    if (size && !in.read(&bytes[0], static_cast<std::streamsize>(size)))
        throw IOError(path + ": read failed");
    return bytes;
}

// The image names meta.json refers to, each once.
std::vector<std::string> image_names(const sog::Meta& m) {
    std::vector<std::string> names{m.means_files[0], m.means_files[1], m.quats_file, m.scales_file, m.sh0_file};
    if (m.has_shn) names.insert(names.end(), m.shn_files.begin(), m.shn_files.end());
    return names;
}

GaussianCloud read_zip(const io::ZipReader& zip, const std::string& name, const SogReadLimits& limits) {
    const io::ZipEntryInfo* meta_entry = zip.find("meta.json");
    if (!meta_entry) throw IOError(name + ": a zip archive without meta.json, not a SOG");
    SogFiles files;
    const auto meta_bytes = zip.read(zip.index_of(*meta_entry), sog::kMaxMetaBytes);
    std::string& meta_text = files["meta.json"];
    meta_text.assign(meta_bytes.begin(), meta_bytes.end());
    const sog::Meta meta = sog::parse_meta(meta_text, name + "/meta.json", limits.max_gaussians);
    for (const std::string& image : image_names(meta)) {
        if (files.count(image)) continue;
        const io::ZipEntryInfo* e = zip.find(image);
        if (!e) throw IOError(name + "/" + image + ": missing from the archive (named by meta.json)");
        const auto bytes = zip.read(zip.index_of(*e), max_image_bytes(meta.count));
        files[image].assign(bytes.begin(), bytes.end());
    }
    return decode_sog(files, name, limits);
}

GaussianCloud read_folder(const std::string& folder, const std::string& meta_path, const SogReadLimits& limits) {
    SogFiles files;
    std::string& meta_text = files["meta.json"];
    meta_text = read_bounded(meta_path, sog::kMaxMetaBytes, "meta.json");
    const sog::Meta meta = sog::parse_meta(meta_text, meta_path, limits.max_gaussians);
    for (const std::string& image : image_names(meta)) {
        if (files.count(image)) continue;
        const std::string path = folder + "/" + image;
        struct stat st;
        if (::stat(path.c_str(), &st) != 0)
            throw IOError(path + ": missing (named by " + meta_path + "): " + std::strerror(errno));
        files[image] = read_bounded(path, max_image_bytes(meta.count), "image");
    }
    return decode_sog(files, folder, limits);
}

bool ends_with(const std::string& s, const std::string& suffix) {
    if (s.size() < suffix.size()) return false;
    for (std::size_t i = 0; i < suffix.size(); ++i)
        if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) != suffix[i]) return false;
    return true;
}

}  // namespace

GaussianCloud read_sog(const std::string& path, const SogReadLimits& limits) {
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) {
        const std::string meta = path + "/meta.json";
        if (::stat(meta.c_str(), &st) != 0)
            throw IOError(path + ": a folder without meta.json, not a SOG");
        return read_folder(path, meta, limits);
    }
    io::regular_file_size(path);
    std::string head(4, '\0');
    {
        std::ifstream in(path, std::ios::binary);
        if (!in) throw IOError(path + ": cannot open for reading: " + std::strerror(errno));
        in.read(&head[0], 4);
        head.resize(static_cast<std::size_t>(in.gcount()));
    }
    if (is_zip(head)) return read_zip(io::ZipReader::open_file(path), path, limits);
    return read_folder(parent(path), path, limits);
}

bool is_sog(const std::string& path) {
    try {
        struct stat st;
        if (::stat(path.c_str(), &st) != 0) return false;
        if (S_ISDIR(st.st_mode)) return ::stat((path + "/meta.json").c_str(), &st) == 0;
        if (!S_ISREG(st.st_mode)) return false;
        std::string head(4, '\0');
        {
            std::ifstream in(path, std::ios::binary);
            in.read(&head[0], 4);
            head.resize(static_cast<std::size_t>(in.gcount()));
        }
        if (is_zip(head)) return io::ZipReader::open_file(path).find("meta.json") != nullptr;
        if (!ends_with(path, ".json") || std::uint64_t(st.st_size) > sog::kMaxMetaBytes) return false;
        const auto j = nlohmann::json::parse(read_bounded(path, sog::kMaxMetaBytes, "meta.json"), nullptr, false);
        return j.is_object() && j.contains("means") && j.contains("quats");
    } catch (const std::exception&) {
        return false;
    }
}

GaussianCloud parse_sog(const void* data, std::size_t size, const std::string& name, const SogReadLimits& limits) {
    return read_zip(io::ZipReader::open_memory(data, size, name), name, limits);
}

void write_sog(const std::string& path, const GaussianCloud& cloud, const SogWriteOptions& options) {
    const SogFiles files = encode_sog(cloud, options);
    if (ends_with(path, ".sog")) {
        // meta.json first, as splat-transform writes it, so a reader finds it at once.
        std::vector<io::ZipWriteEntry> entries;
        auto add = [&entries](const std::string& name, const std::string& bytes) {
            entries.push_back({name, reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), false});
        };
        add("meta.json", files.at("meta.json"));
        for (const auto& [name, bytes] : files)
            if (name != "meta.json") add(name, bytes);
        io::write_zip(path, entries);
        return;
    }
    std::string folder = path, meta_path = path + "/meta.json";
    if (ends_with(path, ".json")) {
        folder = parent(path);
        meta_path = path;
    } else if (::mkdir(path.c_str(), 0777) != 0 && errno != EEXIST) {
        throw IOError(path + ": cannot create the SOG folder: " + std::strerror(errno));
    }
    // The images first and meta.json last: a reader that finds the new meta.json finds its images.
    for (const auto& [name, bytes] : files)
        if (name != "meta.json") write_file_atomically(folder + "/" + name, bytes);
    write_file_atomically(meta_path, files.at("meta.json"));
}

}  // namespace avsplat
