// libFuzzer harness for one avsplat reader, chosen at compile time by AVSPLAT_FUZZ_READER
// (tests/fuzz/CMakeLists.txt builds one executable per reader from this file).
//
// The input reaches the reader as a file, because the path-based entry points are what users
// call: it is written to a tmpfs file named with the reader's extension (read_gaussians picks
// the format from the name). A reader may answer with avsplat::IOError (a bad file) or
// std::invalid_argument (a value the data model rejects); anything else is a finding: a crash,
// a sanitizer report, a hang (libFuzzer's -timeout), an allocation beyond -malloc_limit_mb, or
// any other exception, which escapes and aborts the run.
#include "avsplat/core/error.h"
#include "avsplat/io/camera_json.h"
#include "avsplat/io/compressed_ply.h"
#include "avsplat/io/gaussian_io.h"
#include "avsplat/io/glb.h"
#include "avsplat/io/ksplat.h"
#include "avsplat/io/lod_set.h"
#include "avsplat/io/npz.h"
#include "avsplat/io/ply.h"
#include "avsplat/io/ply_data.h"
#include "avsplat/io/splat.h"
#include "avsplat/io/spz.h"
#include "avsplat/io/sog.h"

#include <unistd.h>
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

#define AVSPLAT_FUZZ_STR2(x) #x
#define AVSPLAT_FUZZ_STR(x) AVSPLAT_FUZZ_STR2(x)

// One file per process, reused for every input and removed at exit.
const std::string& input_path() {
    static const std::string path = [] {
        std::atexit([] { std::remove(input_path().c_str()); });
        return "/dev/shm/avsplat_fuzz_" + std::to_string(::getpid()) + "." +
               AVSPLAT_FUZZ_STR(AVSPLAT_FUZZ_EXTENSION);
    }();
    return path;
}

void write_input(const std::uint8_t* data, std::size_t size) {
    std::FILE* f = std::fopen(input_path().c_str(), "wb");
    if (!f) std::abort();
    if (size && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
}

void run_reader(const std::uint8_t* data, std::size_t size) {
    const std::string& path = input_path();
    (void)path;
#if AVSPLAT_FUZZ_READER_ply
    write_input(data, size);
    avsplat::read_ply(path);
#elif AVSPLAT_FUZZ_READER_ply_data
    avsplat::parse_ply_data(data, size, "fuzz input");
#elif AVSPLAT_FUZZ_READER_splat
    write_input(data, size);
    avsplat::read_splat(path);
#elif AVSPLAT_FUZZ_READER_gaussians
    write_input(data, size);
    avsplat::read_gaussians(path);
#elif AVSPLAT_FUZZ_READER_npz
    write_input(data, size);
    avsplat::read_npz(path);
#elif AVSPLAT_FUZZ_READER_npy
    // The in-memory parser (npz entries) and the file reader share it; fuzz it directly.
    avsplat::parse_npy(data, size, "fuzz input", "x");
#elif AVSPLAT_FUZZ_READER_cameras
    write_input(data, size);
    avsplat::read_cameras_json(path);
#elif AVSPLAT_FUZZ_READER_spz
    // In memory: the file reader only adds reading the bytes.
    avsplat::parse_spz(data, size, "fuzz input");
#elif AVSPLAT_FUZZ_READER_spz_raw
    // The input is a v2/v3 payload (header, extensions, attribute blocks): gzipped here, so that
    // mutations reach the header and attribute decoding instead of failing the gzip CRC.
    z_stream z{};
    if (deflateInit2(&z, 1, Z_DEFLATED, 16 + MAX_WBITS, 8, Z_DEFAULT_STRATEGY) != Z_OK) std::abort();
    std::vector<std::uint8_t> gz(deflateBound(&z, static_cast<uLong>(size)) + 32);
    z.next_in = const_cast<Bytef*>(data);
    z.avail_in = static_cast<uInt>(size);
    z.next_out = gz.data();
    z.avail_out = static_cast<uInt>(gz.size());
    if (deflate(&z, Z_FINISH) != Z_STREAM_END) std::abort();
    gz.resize(z.total_out);
    deflateEnd(&z);
    avsplat::parse_spz(gz.data(), gz.size(), "fuzz input");
#elif AVSPLAT_FUZZ_READER_sog
    // A .sog zip; a count is capped at 2^20 Gaussians so that a lying meta.json stays inside
    // libFuzzer's memory limit (the cap is checked before anything is allocated).
    write_input(data, size);
    avsplat::SogReadLimits limits;
    limits.max_gaussians = std::size_t(1) << 20;
    avsplat::read_sog(path, limits);
#elif AVSPLAT_FUZZ_READER_sog_meta
    // meta.json against the valid images of a small SH degree 1 SOG: lying counts, codebooks,
    // bounds and file names meet real images.
    static const avsplat::SogFiles images = [] {
        avsplat::GaussianCloud c(40, 1);
        for (std::size_t i = 0; i < c.size(); ++i) {
            c.means[3 * i] = float(i) * 0.1f;
            c.sh[12 * i + 3 + i % 9] = 0.25f;
        }
        return avsplat::encode_sog(c);
    }();
    avsplat::SogFiles files = images;
    files["meta.json"].assign(reinterpret_cast<const char*>(data), size);
    avsplat::SogReadLimits limits;
    limits.max_gaussians = std::size_t(1) << 20;
    avsplat::decode_sog(files, "fuzz input", limits);
#elif AVSPLAT_FUZZ_READER_lod_meta
    // lod-meta.json beside the valid SOG chunks of a small two-level set (the seed's layout):
    // lying trees, ranges, counts and file names meet real chunks.
    // Never destroyed, so that the removal at exit can still name it.
    static const std::string& folder = *[] {
        auto* f = new std::string("/dev/shm/avsplat_fuzz_lod_" + std::to_string(::getpid()));
        avsplat::GaussianCloud c(40, 1);
        for (std::size_t i = 0; i < c.size(); ++i) {
            c.means[3 * i] = float(i) * 0.1f;
            c.means[3 * i + 1] = float(i % 7) * 0.2f;
            c.sh[12 * i + 3 + i % 9] = 0.25f;
        }
        std::vector<std::size_t> half;
        for (std::size_t i = 0; i < c.size(); i += 2) half.push_back(i);
        avsplat::LodWriteOptions o;
        o.node_size = 12;
        o.chunk_size = 16;
        avsplat::write_lod_set(*f + "/lod-meta.json", {c, avsplat::select(c, half)}, o);
        std::atexit([] {
            if (std::system(("rm -rf '" + folder + "'").c_str()) != 0) std::fputs("could not remove the fuzz folder\n", stderr);
        });
        return f;
    }();
    const std::string meta = folder + "/fuzz-meta.json";
    {
        std::FILE* f = std::fopen(meta.c_str(), "wb");
        if (!f) std::abort();
        if (size && std::fwrite(data, 1, size, f) != size) std::abort();
        std::fclose(f);
    }
    avsplat::read_lod_set(meta);
#elif AVSPLAT_FUZZ_READER_compressed_ply
    avsplat::parse_compressed_ply(data, size, "fuzz input");
#elif AVSPLAT_FUZZ_READER_glb
    // In memory: the file reader only adds reading the bytes.
    avsplat::parse_glb(data, size, "fuzz input");
#elif AVSPLAT_FUZZ_READER_ksplat
    avsplat::parse_ksplat(data, size, "fuzz input");
#else
#error "AVSPLAT_FUZZ_READER_<name> is not set to a known reader"
#endif
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    try {
        run_reader(data, size);
    } catch (const avsplat::IOError&) {
    } catch (const std::invalid_argument&) {
    }
    return 0;
}
