// Writing the 3DGS parameterisation of PLY (io/ply.h): write_ply for a whole cloud, and
// GaussianPlyWriter for a cloud that arrives in parts. Both write the same bytes for the same
// Gaussians: one header builder, one row encoder.
#include "avsplat/io/ply.h"

#include "avsplat/core/error.h"
#include "avsplat/io/atomic_file.h"
#include "avsplat/io/gaussian_io.h"
#include "io/chunk_pipeline.h"
#include "io/ply/gaussian_activations.h"
#include "io/ply/ply_format.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <memory>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace avsplat {

namespace {

bool starts_with(std::string_view s, std::string_view prefix) {
    return s.size() >= prefix.size() && s.substr(0, prefix.size()) == prefix;
}

// Extra channels become PLY properties: their names must be single tokens that a reader will
// not take for one of the 3DGS properties.
void check_extra_names(const GaussianCloud& cloud) {
    for (std::size_t k = 0; k < cloud.extras.size(); ++k) {
        const std::string& name = cloud.extras[k].name;
        const std::string field = "GaussianCloud.extras['" + name + "']";
        if (name.empty()) throw std::invalid_argument("GaussianCloud.extras[" + std::to_string(k) + "]: empty name");
        for (char ch : name) {
            if (static_cast<unsigned char>(ch) <= ' ' || ch == 127)
                throw std::invalid_argument(field + ": a PLY property name cannot contain spaces or control characters");
        }
        static const char* kReserved[] = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
                                          "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1",
                                          "rot_2", "rot_3", "confidence"};
        bool reserved = starts_with(name, "f_rest_");
        for (const char* r : kReserved) reserved = reserved || name == r;
        if (reserved) throw std::invalid_argument(field + ": the name is a 3DGS PLY property");
        for (std::size_t j = 0; j < k; ++j)
            if (cloud.extras[j].name == name) throw std::invalid_argument(field + ": duplicate extra channel name");
    }
}

// What a PLY header says besides the count: the SH degree, confidence, extra channel names.
struct Schema {
    int sh_degree = 0;
    bool confidence = false;
    std::vector<std::string> extras;

    explicit Schema(const GaussianCloud& c) : sh_degree(c.sh_degree), confidence(c.has_confidence()) {
        for (const auto& e : c.extras) extras.push_back(e.name);
    }
    bool operator==(const Schema& o) const {
        return sh_degree == o.sh_degree && confidence == o.confidence && extras == o.extras;
    }
};

// The header for n vertices of schema s.
std::string vertex_header(const Schema& s, std::size_t n) {
    const std::size_t rest = 3u * static_cast<std::size_t>((s.sh_degree + 1) * (s.sh_degree + 1) - 1);
    std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) + "\n";
    for (const char* name : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
        header += std::string("property float ") + name + "\n";
    for (std::size_t k = 0; k < rest; ++k) header += "property float f_rest_" + std::to_string(k) + "\n";
    for (const char* name : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
        header += std::string("property float ") + name + "\n";
    if (s.confidence) header += "property float confidence\n";
    for (const auto& e : s.extras) header += "property float " + e + "\n";
    header += "end_header\n";
    return header;
}


// Encodes every row of `cloud` and hands the bytes to write(data, bytes) in chunks of about
// 8 MB. Rows are encoded in parallel (each is independent; the logs of opacity and scale in bulk,
// gaussian_activations.h) while the previous chunk is being written (chunk_pipeline.h), so the
// encoding hides behind the write and the write behind the encoding.
template <class Write>
void encode_rows(const GaussianCloud& cloud, const Write& write) {
    const std::size_t n = cloud.size();
    const int K = cloud.sh_coeffs();
    const std::size_t floats = 17 + 3u * std::size_t(K - 1) + (cloud.has_confidence() ? 1 : 0) + cloud.extras.size();
    const std::size_t rows_per_chunk = std::max<std::size_t>(1, (8u << 20) / (4 * floats));
    const std::size_t chunks = (n + rows_per_chunk - 1) / rows_per_chunk;
    constexpr std::size_t kBlock = 1024;  // rows whose activations are encoded in one bulk call
    auto fill = [&](std::size_t chunk, char* bytes) {
        float* const buf = reinterpret_cast<float*>(bytes);
        const std::size_t first = chunk * rows_per_chunk;
        const std::size_t rows = std::min(rows_per_chunk, n - first);
        const long long blocks = static_cast<long long>((rows + kBlock - 1) / kBlock);
#pragma omp parallel for schedule(static)
        for (long long blk = 0; blk < blocks; ++blk) {
            const std::size_t b0 = static_cast<std::size_t>(blk) * kBlock, b1 = std::min(rows, b0 + kBlock);
            float opacity[kBlock], scale[3 * kBlock];
            ply::encode_opacities(cloud.opacities.data() + first + b0, opacity, b1 - b0);
            ply::encode_scales(cloud.scales.data() + 3 * (first + b0), scale, 3 * (b1 - b0));
            for (std::size_t k = b0; k < b1; ++k) {
                const std::size_t i = first + k;
                float* o = buf + k * floats;
                const float* sh = cloud.sh.data() + i * 3 * K;
                *o++ = cloud.means[3 * i + 0];
                *o++ = cloud.means[3 * i + 1];
                *o++ = cloud.means[3 * i + 2];
                *o++ = 0.0f;
                *o++ = 0.0f;
                *o++ = 0.0f;
                *o++ = sh[0];
                *o++ = sh[1];
                *o++ = sh[2];
                for (int c = 0; c < 3; ++c)
                    for (int j = 1; j < K; ++j) *o++ = sh[3 * j + c];
                *o++ = opacity[k - b0];
                for (int a = 0; a < 3; ++a) *o++ = scale[3 * (k - b0) + a];
                for (int a = 0; a < 4; ++a) *o++ = cloud.rotations[4 * i + a];
                if (cloud.has_confidence()) *o++ = cloud.confidence[i];
                for (const auto& e : cloud.extras) *o++ = e.values[i];
            }
        }
        if (!ply::kHostLittleEndian) {
            for (std::size_t k = 0; k < rows * floats; ++k) {
                unsigned char b[4];
                std::memcpy(b, &buf[k], 4);
                std::swap(b[0], b[3]);
                std::swap(b[1], b[2]);
                std::memcpy(&buf[k], b, 4);
            }
        }
        return rows * floats * 4;
    };
    detail::pipeline_chunks(chunks, std::min(n, rows_per_chunk) * floats * 4, fill,
                            [&](const char* data, std::size_t bytes) { write(data, bytes); });
}

// The folder of `path` ("." when it has none), where the rows' scratch file goes: the same file
// system as the output, so that its space is the output's.
std::string folder_of(const std::string& path) {
    const std::size_t slash = path.rfind('/');
    if (slash == std::string::npos) return ".";
    return slash == 0 ? "/" : path.substr(0, slash);
}

}  // namespace

void write_ply(const std::string& path, const GaussianCloud& cloud) {
    // A PLY file under a name that says SOG (or SPZ, .splat, compressed PLY) would be misread by
    // whoever trusts the name; write_gaussians is the writer that follows the name.
    GaussianFormat named = GaussianFormat::Ply;
    try {
        named = gaussian_format_for_name(path);
    } catch (const IOError&) {
        // an extension no Gaussian format claims: write_ply writes PLY under any such name
    }
    if (named != GaussianFormat::Ply)
        throw IOError(path + ": write_ply writes 3DGS PLY, but the name says " + gaussian_format_name(named) +
                      " (name it .ply, or call write_gaussians, which writes the format the name says)");
    validate(cloud);
    check_extra_names(cloud);
    AtomicFile out(path);
    out.write(vertex_header(Schema(cloud), cloud.size()));
    encode_rows(cloud, [&](const void* data, std::size_t bytes) { out.write(data, bytes); });
    out.commit();
}

std::string ply_bytes(const GaussianCloud& cloud) {
    validate(cloud);
    check_extra_names(cloud);
    std::string bytes = vertex_header(Schema(cloud), cloud.size());
    encode_rows(cloud, [&](const void* data, std::size_t n) { bytes.append(static_cast<const char*>(data), n); });
    return bytes;
}

struct GaussianPlyWriter::State {
    int fd = -1;  // the unlinked scratch file of rows
    std::unique_ptr<AtomicFile> out;
    std::unique_ptr<Schema> schema;  // set by the first part
    bool schema_from_empty = false;
    ~State() {
        if (fd >= 0) ::close(fd);
    }
};

GaussianPlyWriter::GaussianPlyWriter(const std::string& path) : path_(path), state_(std::make_unique<State>()) {
    // The destination's temporary file is created now, so that a bad path fails before any work
    // is done; the rows wait in an unlinked scratch file beside it, which the file system
    // reclaims however the process ends.
    state_->out = std::make_unique<AtomicFile>(path_);
    std::string templ = folder_of(path_) + "/.avsplat-rows-XXXXXX";
    state_->fd = ::mkstemp(templ.data());
    if (state_->fd < 0) throw IOError(path_ + ": cannot create a scratch file beside it: " + std::strerror(errno));
    ::unlink(templ.c_str());
}

GaussianPlyWriter::~GaussianPlyWriter() = default;

void GaussianPlyWriter::append(const GaussianCloud& part) {
    if (committed_) throw std::logic_error("GaussianPlyWriter::append after commit or abort");
    validate(part);
    // An empty part cannot say whether it has a confidence (GaussianCloud::has_confidence is its
    // array's size), so only a non-empty part fixes the schema, and an empty one is checked for
    // the rest; with only empty parts, the first of them gives the header.
    Schema schema(part);
    if (!state_->schema || (state_->schema_from_empty && part.size())) {
        check_extra_names(part);
        state_->schema = std::make_unique<Schema>(schema);
        state_->schema_from_empty = part.size() == 0;
    } else {
        if (part.size() == 0) schema.confidence = state_->schema->confidence;
        if (!(schema == *state_->schema))
            throw std::invalid_argument("GaussianPlyWriter::append: the part's SH degree, confidence or extra "
                                        "channels differ from the first part's");
    }
    encode_rows(part, [&](const void* data, std::size_t bytes) {
        const char* p = static_cast<const char*>(data);
        while (bytes) {
            const ssize_t w = ::write(state_->fd, p, bytes);
            if (w < 0 && errno == EINTR) continue;
            if (w <= 0)
                throw OutputError(path_ + ": write failed (scratch file beside it): " +
                                  std::strerror(w < 0 ? errno : ENOSPC));
            p += w;
            bytes -= std::size_t(w);
        }
    });
    size_ += part.size();
}

void GaussianPlyWriter::abort() noexcept {
    committed_ = true;
    state_->out.reset();  // removes the temporary file
    if (state_->fd >= 0) ::close(state_->fd);
    state_->fd = -1;
}

void GaussianPlyWriter::commit() {
    if (committed_) throw std::logic_error("GaussianPlyWriter::commit called twice, or after abort");
    try {
        write_out();
    } catch (...) {
        abort();
        throw;
    }
}

void GaussianPlyWriter::write_out() {
    committed_ = true;
    const Schema schema = state_->schema ? *state_->schema : Schema(GaussianCloud());
    AtomicFile& out = *state_->out;
    out.write(vertex_header(schema, size_));
    if (::lseek(state_->fd, 0, SEEK_SET) < 0)
        throw IOError(path_ + ": cannot rewind the scratch file: " + std::strerror(errno));
    std::vector<char> buf(8u << 20);
    for (;;) {
        const ssize_t r = ::read(state_->fd, buf.data(), buf.size());
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) throw IOError(path_ + ": cannot read the scratch file back: " + std::strerror(errno));
        if (r == 0) break;
        out.write(buf.data(), std::size_t(r));
    }
    out.commit();
    state_->out.reset();
    ::close(state_->fd);
    state_->fd = -1;
}

}  // namespace avsplat
