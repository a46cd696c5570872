// The standard 3DGS ("INRIA") vertex layout, read with every offset known at compile time: the
// fast path of read_ply (gaussian_ply.cpp) for files that start with it; every other layout goes
// through the generic per-property path there. Internal to io/ply.
#pragma once

#include "io/ply/ply_format.h"

#ifdef __SSE2__
#include <immintrin.h>
#endif

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace avsplat::ply {

// The INRIA layout's leading properties: x y z, nx ny nz (optional), f_dc_0..2,
// f_rest_0..3(K-1)-1, opacity, scale_0..2, rot_0..3, every one a native float32. Other
// properties may follow (confidence, extras). Returns how many properties the prefix has (0 when
// the file does not start with it).
inline std::size_t standard_prefix(const Element& vertex, bool swap, int K, bool* normals) {
    if (swap) return 0;
    std::vector<std::string> names = {"x", "y", "z"};
    *normals = vertex.properties.size() > 3 && vertex.properties[3].name == "nx";
    if (*normals) names.insert(names.end(), {"nx", "ny", "nz"});
    names.insert(names.end(), {"f_dc_0", "f_dc_1", "f_dc_2"});
    for (int k = 0; k < 3 * (K - 1); ++k) names.push_back("f_rest_" + std::to_string(k));
    names.insert(names.end(), {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"});
    if (vertex.properties.size() < names.size()) return 0;
    for (std::size_t k = 0; k < names.size(); ++k)
        if (vertex.properties[k].name != names[k] || vertex.properties[k].type != PlyType::Float32) return 0;
    return names.size();
}

// The output arrays at row 0.
struct StandardOutputs {
    float* means;
    float* sh;
    float* opacities;
    float* scales;
    float* rotations;
};

// The standard prefix of `rows` rows, with every offset known at compile time. Opacities and
// scales are copied as stored (logit, log) and decoded in bulk afterwards.
template <int K, bool kNormals>
void copy_standard_rows(const unsigned char* src, std::size_t row, std::size_t first, std::size_t rows, const StandardOutputs& o) {
    constexpr int kDc = kNormals ? 6 : 3;
    constexpr int kRest = kDc + 3;
    constexpr int kOpacity = kRest + 3 * (K - 1);
    constexpr int kScale = kOpacity + 1;
    constexpr int kRot = kScale + 3;
    constexpr int kFloats = kRot + 4;
    // The SH rows and rotations (four fifths of the output) go to memory with streaming stores
    // where whole 16-byte words line up: they are not read again here, and a plain store would
    // first read every line back from memory (the fresh arrays no longer fit in any cache).
#ifdef __SSE2__
    const bool stream = (3 * K) % 4 == 0 && reinterpret_cast<std::uintptr_t>(o.sh) % 16 == 0 &&
                        reinterpret_cast<std::uintptr_t>(o.rotations) % 16 == 0;
#else
    const bool stream = false;
#endif
    for (std::size_t i = first; i < first + rows; ++i, src += row) {
        float f[kFloats];
        std::memcpy(f, src, sizeof f);
        float sh[3 * K];
        for (int c = 0; c < 3; ++c) sh[c] = f[kDc + c];
        // Channel-major on disk: f_rest_{c*(K-1)+j} is coefficient j+1 of channel c.
        for (int j = 0; j < K - 1; ++j)
            for (int c = 0; c < 3; ++c) sh[3 * (j + 1) + c] = f[kRest + c * (K - 1) + j];
        for (int c = 0; c < 3; ++c) o.means[3 * i + c] = f[c];
        o.opacities[i] = f[kOpacity];
        for (int c = 0; c < 3; ++c) o.scales[3 * i + c] = f[kScale + c];
#ifdef __SSE2__
        if (stream) {
            for (int k = 0; k + 4 <= 3 * K; k += 4) _mm_stream_ps(o.sh + 3 * K * i + k, _mm_loadu_ps(sh + k));
            _mm_stream_ps(o.rotations + 4 * i, _mm_loadu_ps(f + kRot));
            continue;
        }
#endif
        std::memcpy(o.sh + 3 * K * i, sh, sizeof sh);
        std::memcpy(o.rotations + 4 * i, f + kRot, 4 * sizeof(float));
    }
#ifdef __SSE2__
    if (stream) _mm_sfence();  // the streamed stores are visible before the piece counts as done
#endif
}

}  // namespace avsplat::ply
