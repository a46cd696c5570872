// Spill files of FusionStream: samples as a table of float columns plus each sample's global
// index, appended to a file segment by segment and read back segment by segment, so that
// neither side ever holds more than one segment.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace avsplat::detail {

/// Samples in column-major blocks: column c holds widths[c] floats per sample.
struct SampleTable {
    std::vector<int> widths;
    std::vector<std::uint64_t> index;  ///< global sample index, in the order samples were added
    std::vector<std::vector<float>> columns;

    explicit SampleTable(std::vector<int> w = {}) : widths(std::move(w)), columns(widths.size()) {}
    std::size_t size() const noexcept { return index.size(); }
    std::size_t bytes_per_sample() const noexcept;
    std::size_t bytes() const noexcept { return size() * bytes_per_sample(); }
    void clear();
    /// Appends rows[0..n) of src (same widths), in that order.
    void append_rows(const SampleTable& src, const std::uint32_t* rows, std::size_t n);
    /// Appends all of src.
    void append(const SampleTable& src);
};

/// One block's file. Throws avsplat::IOError naming the file when it cannot be written or read.
class SpillFile {
public:
    explicit SpillFile(std::string path) : path_(std::move(path)) {}
    const std::string& path() const noexcept { return path_; }
    std::size_t samples() const noexcept { return samples_; }
    std::size_t bytes() const noexcept { return bytes_; }
    /// Writes `table` as one segment at the end of the file.
    void append(const SampleTable& table);
    /// Calls f on each segment in the order written (the table is reused between calls).
    void for_each_segment(const std::vector<int>& widths, const std::function<void(const SampleTable&)>& f) const;
    /// Reads the whole file into one table.
    SampleTable read_all(const std::vector<int>& widths) const;
    /// Deletes the file (no error when it is already gone).
    void remove() noexcept;

private:
    std::string path_;
    std::size_t samples_ = 0;
    std::size_t bytes_ = 0;
};

}  // namespace avsplat::detail
