#include "avsplat/fusion/fusion_stream.h"

#include "avsplat/core/error.h"
#include "avsplat/fusion/voxel_grid.h"
#include "common/stale_scratch.h"
#include "core/progress_report.h"
#include "core/gaussian_validity.h"
#include "core/invalid_samples.h"
#include "fusion/checks.h"
#include "fusion/spill_file.h"
#include "fusion/stream_checks.h"
#include "fusion/stream_keys.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

namespace avsplat {

namespace {

using detail::Key;
using detail::ChunkChecks;
using detail::SampleTable;
using detail::SpillFile;
using detail::block_of;
using detail::globalise_message;
using detail::kKeyHigh;
using detail::kKeyLow;
using detail::position_error;
using detail::quantile_bounds;

constexpr std::size_t kDefaultMemoryLimit = std::size_t(1) << 30;
// Blocks chosen at the first spill. More blocks cost more, smaller writes per spill; too few
// cost a re-split pass in finish(). Either way the result is the same.
constexpr std::size_t kInitialBlocks = 64;
constexpr std::size_t kMaxSplit = 4096;

enum class Mode { None, Features, Gaussians };

template <class T>
void append(std::vector<T>& dst, const std::vector<T>& src) {
    dst.insert(dst.end(), src.begin(), src.end());
}

}  // namespace

void VoxelDiagnostics::append(const VoxelDiagnostics& o) {
    avsplat::append(occupancy, o.occupancy);
    avsplat::append(temperature, o.temperature);
    avsplat::append(variance, o.variance);
    avsplat::append(reliability, o.reliability);
    avsplat::append(kept, o.kept);
    avsplat::append(entropy, o.entropy);
}

struct FusionStream::State {
    double voxel_size = 0;
    FusionParams params;
    std::size_t memory_limit = 0;
    std::string work_dir;
    std::string folder;  // created at the first spill
    int lock_fd = -1;    // its lock file, held open (and locked) while the folder exists
    Mode mode = Mode::None;
    bool finished = false;

    // Schema fixed by the first chunk.
    int channels = 0;
    bool has_confidence = false;
    int sh_degree = 0;
    std::vector<std::string> extra_names;
    std::vector<int> widths;

    std::size_t samples = 0;
    std::size_t dropped_at_add = 0;  // samples dropped by the checks in add (on_invalid = Drop)
    SampleTable pending;
    SampleTable scratch;  // one block's rows while routing, reused
    std::vector<Key> bounds;  // empty while nothing has been spilled
    std::vector<SpillFile> files;
    std::size_t spilled = 0;
    std::size_t next_file = 0;

    FusionStream::Progress progress;

    // Set while a call runs: a second thread's call is refused instead of racing on the buffers.
    std::atomic<bool> busy{false};
    // Why the stream was closed by a failure part-way through an add (empty while usable).
    std::string closed_by;

    ~State() { remove_folder(); }

    // Marks the stream busy for one call; refuses a concurrent call and a closed stream.
    class Use {
    public:
        explicit Use(State& s) : s_(s) {
            if (s_.busy.exchange(true))
                throw std::logic_error("FusionStream: called while another call on it runs (on another thread, or from "
                                       "its progress callback); a stream is not thread-safe, so feed it from one "
                                       "thread or hold a lock around each call");
            if (!s_.closed_by.empty()) {
                s_.busy.store(false);
                throw std::logic_error("FusionStream: closed because an earlier add failed (" + s_.closed_by +
                                       "); start a new stream");
            }
        }
        ~Use() { s_.busy.store(false); }
        Use(const Use&) = delete;
        Use& operator=(const Use&) = delete;

    private:
        State& s_;
    };

    // A failure while taking a chunk (a spill file that cannot be written, memory) can leave the
    // pending table and the spill files out of step: the stream is closed and its files removed.
    template <class F>
    void or_close(const F& f) {
        try {
            f();
        } catch (const std::exception& e) {
            closed_by = e.what();
            if (closed_by.empty()) closed_by = "unknown error";
            remove_folder();
            throw;
        }
    }

    std::size_t target_bytes() const { return std::max<std::size_t>(memory_limit / 4, 1); }

    void remove_folder() noexcept {
        if (folder.empty()) return;
        std::error_code ec;
        std::filesystem::remove_all(folder, ec);
        folder.clear();
        if (lock_fd >= 0) ::close(lock_fd);
        lock_fd = -1;
    }

    // "avsplat-fusion-PID-XXXXXX" holding a ".lock" file locked while this process lives, so that
    // the next stream in the same root removes the folders of a process that was killed.
    void make_folder() {
        std::error_code ec;
        const std::filesystem::path root =
            work_dir.empty() ? std::filesystem::temp_directory_path(ec) : std::filesystem::path(work_dir);
        if (ec)  // TMPDIR names no folder: never fall back to the current one
            throw OutputError(std::string(std::getenv("TMPDIR") ? std::getenv("TMPDIR") : "TMPDIR") +
                              ": cannot create the fusion work folder there: " + ec.message());
        detail::remove_stale_scratch(root.string(), "avsplat-fusion-", true);
        std::string templ = (root / ("avsplat-fusion-" + std::to_string(::getpid()) + "-XXXXXX")).string();
        errno = 0;
        if (!mkdtemp(templ.data()))
            throw OutputError(templ + ": cannot create the fusion work folder: " + std::strerror(errno));
        folder = templ;
        lock_fd = ::open((folder + "/.lock").c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
        if (lock_fd >= 0) detail::lock_scratch(lock_fd);
    }

    SpillFile new_file() {
        if (folder.empty()) make_folder();
        return SpillFile(folder + "/block-" + std::to_string(next_file++) + ".bin");
    }

    // The voxel key of a row, computed as SparseVoxelGrid does (round(p / voxel_size) in double).
    Key key(const SampleTable& t, std::size_t row) const {
        const float* p = t.columns[0].data() + 3 * row;
        return {std::int32_t(std::round(double(p[0]) / voxel_size)), std::int32_t(std::round(double(p[1]) / voxel_size)),
                std::int32_t(std::round(double(p[2]) / voxel_size))};
    }

    void start(Mode m, std::vector<int> w) {
        if (finished) throw std::logic_error("FusionStream: add after finish");
        if (mode == Mode::None) {
            mode = m;
            widths = std::move(w);
            pending = SampleTable(widths);
        } else if (mode != m) {
            throw std::invalid_argument(m == Mode::Features
                                            ? "FusionStream.add: this stream takes Gaussians (add_gaussians)"
                                            : "FusionStream.add_gaussians: this stream takes features (add)");
        }
    }

    // Page faults dominate copying into fresh memory, so the pending buffer is reserved once for
    // what a spill holds and reused after each spill (reservation alone touches no page).
    void reserve_pending(std::size_t chunk) {
        const std::size_t rows = target_bytes() / pending.bytes_per_sample() + chunk;
        pending.index.reserve(rows);
        for (std::size_t c = 0; c < widths.size(); ++c) pending.columns[c].reserve(rows * std::size_t(widths[c]));
    }

    // Input checks of a chunk: stream_checks.h. Its first sample is global index `samples`.
    ChunkChecks checks() { return {params.on_invalid, voxel_size, samples, dropped_at_add}; }

    // Appends the given rows of column-major chunk data (n samples).
    void take(const std::vector<const float*>& cols, std::size_t n, const std::vector<std::uint32_t>& rows) {
        if (pending.index.capacity() == 0) reserve_pending(n);
        for (std::size_t i : rows) pending.index.push_back(samples + i);
        for (std::size_t c = 0; c < widths.size(); ++c) {
            const std::size_t w = std::size_t(widths[c]);
            auto& dst = pending.columns[c];
            if (rows.size() == n) {
                dst.insert(dst.end(), cols[c], cols[c] + n * w);
            } else {
                for (std::uint32_t i : rows) dst.insert(dst.end(), cols[c] + i * w, cols[c] + (i + 1) * w);
            }
        }
        samples += n;
        if (pending.bytes() >= target_bytes()) spill();
    }

    // Routes `t` to the spill files of `bounds` (same length), rows of each block in order.
    void route(const SampleTable& t, const std::vector<Key>& bnds, std::vector<SpillFile>& out) {
        const std::size_t nb = bnds.size();
        std::vector<std::size_t> start(nb + 1, 0);
        std::vector<std::uint32_t> block(t.size());
        for (std::size_t i = 0; i < t.size(); ++i) {
            block[i] = std::uint32_t(block_of(bnds, key(t, i)));
            ++start[block[i] + 1];
        }
        for (std::size_t b = 0; b < nb; ++b) start[b + 1] += start[b];
        std::vector<std::uint32_t> rows(t.size());
        std::vector<std::size_t> at(start.begin(), start.end() - 1);
        for (std::size_t i = 0; i < t.size(); ++i) rows[at[block[i]]++] = std::uint32_t(i);
        SampleTable& part = scratch;
        if (part.widths != widths) part = SampleTable(widths);
        for (std::size_t b = 0; b < nb; ++b) {
            if (start[b + 1] == start[b]) continue;
            part.clear();
            part.append_rows(t, rows.data() + start[b], start[b + 1] - start[b]);
            const std::size_t before = out[b].bytes();
            out[b].append(part);
            spilled += out[b].bytes() - before;
        }
    }

    void spill() {
        if (pending.size() == 0) return;
        if (bounds.empty()) {
            std::vector<Key> keys(pending.size());
            for (std::size_t i = 0; i < keys.size(); ++i) keys[i] = key(pending, i);
            bounds = quantile_bounds(std::move(keys), kInitialBlocks);
            for (std::size_t b = 0; b < bounds.size(); ++b) files.push_back(new_file());
        }
        route(pending, bounds, files);
        pending.clear();
    }

    // Calls fuse(table) for each block of `file` in key order, splitting it first when it is
    // larger than the target and holds more than one voxel. Removes the file.
    template <class Fuse>
    void for_each_block(SpillFile& file, const Fuse& fuse) {
        if (file.bytes() > target_bytes()) {
            std::vector<Key> keys;
            keys.reserve(file.samples());
            file.for_each_segment(widths, [&](const SampleTable& t) {
                for (std::size_t i = 0; i < t.size(); ++i) keys.push_back(key(t, i));
            });
            const std::size_t parts = std::min(kMaxSplit, 2 * (file.bytes() / target_bytes() + 1));
            const std::vector<Key> sub = quantile_bounds(std::move(keys), parts);
            if (sub.size() > 1) {
                std::vector<SpillFile> subs;
                for (std::size_t b = 0; b < sub.size(); ++b) subs.push_back(new_file());
                file.for_each_segment(widths, [&](const SampleTable& t) { route(t, sub, subs); });
                file.remove();
                for (auto& s : subs) for_each_block(s, fuse);
                return;
            }
        }
        SampleTable t = file.read_all(widths);
        file.remove();
        if (t.size()) fuse(t);
    }

    // Calls fuse(table) for every block in key order (the pending table alone when nothing was
    // spilled).
    template <class Fuse>
    void for_each_block(const Fuse& fuse) {
        if (bounds.empty()) {
            if (pending.size()) fuse(pending);
            return;
        }
        spill();
        for (auto& f : files) for_each_block(f, fuse);
    }

    // The finish shared by features and Gaussians: begins it (once, for `mode`), then runs
    // fuse_block(table) on each block in key order, maps the block's sample_voxel into the whole
    // input's, reports progress and hands the block's result to sink. Returns sample_voxel and
    // `dropped` of the whole input, and whether any block was fused. The folder goes whatever
    // happens.
    template <class Result, class FuseBlock, class Sink>
    Result finish_blocks(Mode wanted, const FuseBlock& fuse_block, const Sink& sink, bool& any) {
        if (finished) throw std::logic_error("FusionStream: finish called twice");
        if (mode != Mode::None && mode != wanted)
            throw std::invalid_argument(wanted == Mode::Features
                                            ? "FusionStream.finish: use finish_gaussians for Gaussians"
                                            : "FusionStream.finish_gaussians: use finish for features");
        finished = true;
        struct Cleanup {
            State& s;
            ~Cleanup() { s.remove_folder(); }
        } cleanup{*this};
        Result out;
        out.sample_voxel.assign(samples, -1);
        std::size_t voxels = 0, done = dropped_at_add;
        any = false;
        ProgressReport report(samples);  // the installed callback (core/progress.h), as `progress`
        if (progress) progress(done, samples);
        report.set(done);
        for_each_block([&](SampleTable& t) {
            Result r;
            try {
                r = fuse_block(t);  // may move the table's columns, never its index
            } catch (const std::invalid_argument& e) {
                throw std::invalid_argument(globalise_message(e.what(), t.index));
            }
            for (std::size_t i = 0; i < t.size(); ++i)
                out.sample_voxel[t.index[i]] = r.sample_voxel[i] < 0 ? -1 : std::int32_t(voxels) + r.sample_voxel[i];
            voxels += r.size();
            out.dropped += r.dropped;
            done += t.size();
            r.sample_voxel.clear();
            any = true;
            sink(std::move(r));
            if (progress) progress(done, samples);
            report.set(done);
        });
        report.finish();
        out.dropped += dropped_at_add;
        return out;
    }
};

FusionStream::FusionStream(double voxel_size, const FusionParams& params, std::size_t memory_limit,
                           const std::string& work_dir)
    : state_(std::make_unique<State>()) {
    if (!(voxel_size > 0) || !std::isfinite(voxel_size))
        throw std::invalid_argument("voxel_size: expected a finite number > 0, got " + std::to_string(voxel_size));
    validate(params);
    if (!work_dir.empty() && !std::filesystem::is_directory(work_dir))
        throw IOError(work_dir + ": the fusion work folder does not exist");
    state_->voxel_size = voxel_size;
    state_->params = params;
    state_->memory_limit = memory_limit ? memory_limit : kDefaultMemoryLimit;
    state_->work_dir = work_dir;
}

FusionStream::~FusionStream() = default;

void FusionStream::add(const float* positions, std::size_t n, const float* features, int channels,
                       const float* confidence) {
    State& s = *state_;
    const State::Use use(s);
    if (channels < 0) throw std::invalid_argument("features: channels must be >= 0");
    if (n && !positions) throw std::invalid_argument("positions: null with n > 0");
    if (n && channels && !features) throw std::invalid_argument("features: null with channels > 0");
    const bool conf = confidence != nullptr;
    if (s.mode == Mode::Features) {
        if (channels != s.channels)
            throw std::invalid_argument("features: this chunk has " + std::to_string(channels) +
                                        " channels, the stream " + std::to_string(s.channels));
        if (conf != s.has_confidence)
            throw std::invalid_argument(std::string("confidence: ") +
                                        (conf ? "given, but the stream's first chunk had none"
                                              : "missing, but the stream's first chunk had one"));
    }
    std::vector<int> w{3, channels};
    if (conf) w.push_back(1);
    s.start(Mode::Features, w);
    s.channels = channels;
    s.has_confidence = conf;
    std::vector<const float*> cols{positions, features};
    if (conf) cols.push_back(confidence);
    std::vector<std::uint8_t> keep;
    ChunkChecks checks = s.checks();
    checks.run(keep, [&](std::vector<std::uint8_t>& k) {
        fusion_detail::check_confidence(confidence, n, s.params, "confidence", k);
    });
    const std::vector<std::uint32_t> rows = checks.rows_with_keys(positions, n, keep, "positions");
    checks.features(features, n, std::size_t(channels));
    s.or_close([&] { s.take(cols, n, rows); });
}

void FusionStream::add_gaussians(const GaussianCloud& chunk) {
    State& s = *state_;
    const State::Use use(s);
    const std::size_t n = chunk.size();
    const std::size_t k = std::size_t(chunk.sh_coeffs());
    if (chunk.means.size() != 3 * n || chunk.scales.size() != 3 * n || chunk.rotations.size() != 4 * n ||
        chunk.sh.size() != 3 * k * n || (chunk.has_confidence() && chunk.confidence.size() != n))
        throw std::invalid_argument("add_gaussians: the chunk's arrays do not all have " + std::to_string(n) +
                                    " rows (means, scales, rotations, sh, confidence)");
    std::vector<std::string> names;
    for (const auto& e : chunk.extras) {
        if (e.values.size() != n)
            throw std::invalid_argument("extras['" + e.name + "']: expected " + std::to_string(n) + " values");
        names.push_back(e.name);
    }
    if (s.mode == Mode::Gaussians) {
        if (chunk.sh_degree != s.sh_degree)
            throw std::invalid_argument("sh: this chunk has SH degree " + std::to_string(chunk.sh_degree) +
                                        ", the stream " + std::to_string(s.sh_degree));
        if (chunk.has_confidence() != s.has_confidence)
            throw std::invalid_argument("confidence: present in some chunks and not in others");
        if (names != s.extra_names) throw std::invalid_argument("extras: the chunks' extra channels differ");
    }
    std::vector<int> w{3, 3, 4, 1, int(3 * k)};
    std::vector<const float*> cols{chunk.means.data(), chunk.scales.data(), chunk.rotations.data(),
                                   chunk.opacities.data(), chunk.sh.data()};
    if (chunk.has_confidence()) {
        w.push_back(1);
        cols.push_back(chunk.confidence.data());
    }
    for (const auto& e : chunk.extras) {
        w.push_back(1);
        cols.push_back(e.values.data());
    }
    s.start(Mode::Gaussians, w);
    s.sh_degree = chunk.sh_degree;
    s.has_confidence = chunk.has_confidence();
    s.extra_names = std::move(names);
    std::vector<std::uint8_t> keep;
    ChunkChecks checks = s.checks();
    checks.run(keep, [&](std::vector<std::uint8_t>& k) {
        const auto bad = [&](std::size_t i) {
            GaussianField field = GaussianField::Means;
            return check_gaussian(chunk, i, field) != GaussianDefect::None;
        };
        apply_invalid_policy(n, bad, s.params.on_invalid, k, [&](std::size_t) { validate(chunk); });
        fusion_detail::check_confidence(chunk.has_confidence() ? chunk.confidence.data() : nullptr, n, s.params,
                                        "GaussianCloud.confidence", k);
    });
    const std::vector<std::uint32_t> rows = checks.rows_with_keys(chunk.means.data(), n, keep, "GaussianCloud.means");
    s.or_close([&] { s.take(cols, n, rows); });
}

void FusionStream::set_progress(Progress progress) {
    const State::Use use(*state_);
    state_->progress = std::move(progress);
}

FeatureFusionResult FusionStream::finish(const FeatureSink& sink) {
    State& s = *state_;
    const State::Use use(s);
    const std::size_t c = std::size_t(s.channels);
    bool any = false;
    FeatureFusionResult out = s.finish_blocks<FeatureFusionResult>(
        Mode::Features,
        [&](SampleTable& t) {
            return fuse_voxels(t.columns[0].data(), t.size(), c ? t.columns[1].data() : nullptr, s.channels,
                               s.voxel_size, s.has_confidence ? t.columns[2].data() : nullptr, s.params);
        },
        sink, any);
    out.channels = s.channels;
    return out;
}

FeatureFusionResult FusionStream::finish() {
    FeatureFusionResult all;
    all.channels = state_->channels;
    FeatureFusionResult out = finish([&](FeatureFusionResult&& r) {
        append(all.positions, r.positions);
        append(all.features, r.features);
        append(all.voxel_coords, r.voxel_coords);
        all.diagnostics.append(r.diagnostics);
    });
    all.sample_voxel = std::move(out.sample_voxel);
    all.dropped = out.dropped;
    return all;
}

GaussianFusionResult FusionStream::finish_gaussians(const GaussianSink& sink) {
    State& s = *state_;
    const State::Use use(s);
    bool any = false;
    GaussianFusionResult out = s.finish_blocks<GaussianFusionResult>(
        Mode::Gaussians,
        [&](SampleTable& t) {
            GaussianCloud cloud;
            cloud.sh_degree = s.sh_degree;
            cloud.means = std::move(t.columns[0]);
            cloud.scales = std::move(t.columns[1]);
            cloud.rotations = std::move(t.columns[2]);
            cloud.opacities = std::move(t.columns[3]);
            cloud.sh = std::move(t.columns[4]);
            std::size_t col = 5;
            if (s.has_confidence) cloud.confidence = std::move(t.columns[col++]);
            for (const auto& name : s.extra_names) cloud.extras.push_back({name, std::move(t.columns[col++])});
            return fuse_gaussians(cloud, s.voxel_size, s.params);
        },
        sink, any);
    if (!any) {
        // Nothing fused: one empty block, the operator's empty result with the stream's schema.
        GaussianCloud empty(0, s.sh_degree);
        for (const auto& name : s.extra_names) empty.extras.push_back({name, {}});
        GaussianFusionResult r = fuse_gaussians(empty, s.voxel_size, s.params);
        r.sample_voxel.clear();
        sink(std::move(r));
    }
    return out;
}

GaussianFusionResult FusionStream::finish_gaussians() {
    GaussianFusionResult all;
    bool any = false;
    GaussianFusionResult out = finish_gaussians([&](GaussianFusionResult&& r) {
        if (!any) {
            all.cloud = std::move(r.cloud);
        } else {
            GaussianCloud& o = all.cloud;
            append(o.means, r.cloud.means);
            append(o.scales, r.cloud.scales);
            append(o.rotations, r.cloud.rotations);
            append(o.opacities, r.cloud.opacities);
            append(o.sh, r.cloud.sh);
            append(o.confidence, r.cloud.confidence);
            for (std::size_t e = 0; e < o.extras.size(); ++e) append(o.extras[e].values, r.cloud.extras[e].values);
        }
        append(all.voxel_coords, r.voxel_coords);
        all.diagnostics.append(r.diagnostics);
        any = true;
    });
    all.sample_voxel = std::move(out.sample_voxel);
    all.dropped = out.dropped;
    return all;
}

bool FusionStream::takes_gaussians() const noexcept { return state_->mode == Mode::Gaussians; }
std::size_t FusionStream::num_samples() const noexcept { return state_->samples; }
std::size_t FusionStream::num_blocks() const noexcept { return state_->next_file; }
std::size_t FusionStream::spilled_bytes() const noexcept { return state_->spilled; }
const std::string& FusionStream::work_folder() const noexcept { return state_->folder; }

}  // namespace avsplat
