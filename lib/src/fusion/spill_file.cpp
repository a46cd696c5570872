#include "fusion/spill_file.h"

#include "avsplat/core/error.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

namespace avsplat::detail {

std::size_t SampleTable::bytes_per_sample() const noexcept {
    std::size_t b = sizeof(std::uint64_t);
    for (int w : widths) b += sizeof(float) * std::size_t(w);
    return b;
}

void SampleTable::clear() {
    index.clear();
    for (auto& c : columns) c.clear();
}

void SampleTable::append_rows(const SampleTable& src, const std::uint32_t* rows, std::size_t n) {
    index.reserve(index.size() + n);
    for (std::size_t i = 0; i < n; ++i) index.push_back(src.index[rows[i]]);
    for (std::size_t c = 0; c < columns.size(); ++c) {
        const std::size_t w = std::size_t(widths[c]);
        auto& dst = columns[c];
        const float* s = src.columns[c].data();
        const std::size_t base = dst.size();
        dst.resize(base + n * w);
        for (std::size_t i = 0; i < n; ++i) std::memcpy(&dst[base + i * w], s + std::size_t(rows[i]) * w, w * sizeof(float));
    }
}

void SampleTable::append(const SampleTable& src) {
    index.insert(index.end(), src.index.begin(), src.index.end());
    for (std::size_t c = 0; c < columns.size(); ++c)
        columns[c].insert(columns[c].end(), src.columns[c].begin(), src.columns[c].end());
}

namespace {

struct FileCloser {
    void operator()(std::FILE* f) const noexcept { std::fclose(f); }
};
using File = std::unique_ptr<std::FILE, FileCloser>;

[[noreturn]] void fail(const std::string& path, const char* what) {
    throw IOError(path + ": " + what + (errno ? std::string(": ") + std::strerror(errno) : std::string()));
}

// A spill file that cannot be written is an output failure (a full or read-only work folder).
[[noreturn]] void fail_output(const std::string& path, const char* what) {
    throw OutputError(path + ": " + what + (errno ? std::string(": ") + std::strerror(errno) : std::string()));
}

}  // namespace

void SpillFile::append(const SampleTable& table) {
    if (table.size() == 0) return;
    errno = 0;
    File f(std::fopen(path_.c_str(), "ab"));
    if (!f) fail_output(path_, "cannot open the spill file for writing");
    const std::uint64_t n = table.size();
    bool ok = std::fwrite(&n, sizeof n, 1, f.get()) == 1 &&
              std::fwrite(table.index.data(), sizeof(std::uint64_t), n, f.get()) == n;
    for (const auto& c : table.columns) ok = ok && (c.empty() || std::fwrite(c.data(), sizeof(float), c.size(), f.get()) == c.size());
    if (!ok || std::fflush(f.get()) != 0) fail_output(path_, "cannot write the spill file (disk full?)");
    samples_ += n;
    bytes_ += table.bytes() + sizeof n;
}

void SpillFile::for_each_segment(const std::vector<int>& widths,
                                 const std::function<void(const SampleTable&)>& f) const {
    if (samples_ == 0) return;
    errno = 0;
    File file(std::fopen(path_.c_str(), "rb"));
    if (!file) fail(path_, "cannot open the spill file for reading");
    SampleTable t(widths);
    std::uint64_t n = 0;
    while (std::fread(&n, sizeof n, 1, file.get()) == 1) {
        t.index.resize(n);
        bool ok = std::fread(t.index.data(), sizeof(std::uint64_t), n, file.get()) == n;
        for (std::size_t c = 0; c < widths.size(); ++c) {
            const std::size_t m = n * std::size_t(widths[c]);
            t.columns[c].resize(m);
            ok = ok && (m == 0 || std::fread(t.columns[c].data(), sizeof(float), m, file.get()) == m);
        }
        if (!ok) fail(path_, "the spill file is truncated");
        f(t);
    }
    if (std::ferror(file.get())) fail(path_, "cannot read the spill file");
}

SampleTable SpillFile::read_all(const std::vector<int>& widths) const {
    SampleTable all(widths);
    all.index.reserve(samples_);
    for (std::size_t c = 0; c < widths.size(); ++c) all.columns[c].reserve(samples_ * std::size_t(widths[c]));
    for_each_segment(widths, [&](const SampleTable& t) { all.append(t); });
    return all;
}

void SpillFile::remove() noexcept {
    std::remove(path_.c_str());
    samples_ = bytes_ = 0;
}

}  // namespace avsplat::detail
