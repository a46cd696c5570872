// Private: the constants of the GLB container and the KHR_gaussian_splatting attribute names
// shared by the .glb reader and writer (avsplat/io/glb.h).
#pragma once

#include <cstdint>
#include <string>

namespace avsplat::io::glb {

constexpr std::uint32_t kMagic = 0x46546C67;      // "glTF"
constexpr std::uint32_t kVersion = 2;
constexpr std::uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr std::uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr std::size_t kHeaderSize = 12;
constexpr std::size_t kChunkHeaderSize = 8;

// Accessor component types (glTF 2.0).
constexpr int kByte = 5120, kUnsignedByte = 5121, kShort = 5122, kUnsignedShort = 5123, kFloat = 5126;
constexpr int kModePoints = 0;

constexpr const char* kExtension = "KHR_gaussian_splatting";
constexpr const char* kRotation = "KHR_gaussian_splatting:ROTATION";
constexpr const char* kScale = "KHR_gaussian_splatting:SCALE";
constexpr const char* kOpacity = "KHR_gaussian_splatting:OPACITY";

// glTF's axes are +Y up, +Z forward, +X left (LUF); avsplat's are OpenCV's RDF. The change is a
// 180-degree turn about z, its own inverse: x and y of positions negate, the quaternion (w, x,
// y, z) becomes (w, -x, -y, z) (the same covariance as the turn applied on the left), and SH
// coefficient j changes sign by the parity of its basis function in x and y.
constexpr float kPositionSign[3] = {-1.f, -1.f, 1.f};
constexpr float kQuaternionSign[4] = {1.f, -1.f, -1.f, 1.f};  // w, x, y, z
// Basis functions (core/sh.h's order): y, z, x | xy, yz, 3z^2-1, xz, x^2-y^2 | y(3x^2-y^2), xyz,
// y(5z^2-1), z(5z^2-3), x(5z^2-1), z(x^2-y^2), x(x^2-3y^2).
constexpr float kShSign[16] = {1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1};

/// "KHR_gaussian_splatting:SH_DEGREE_<degree>_COEF_<n>".
inline std::string sh_attribute(int degree, int n) {
    return std::string(kExtension) + ":SH_DEGREE_" + std::to_string(degree) + "_COEF_" + std::to_string(n);
}

}  // namespace avsplat::io::glb
