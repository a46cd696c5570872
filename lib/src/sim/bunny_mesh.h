// Private: the embedded Stanford bunny, parsed once, as the ray caster uses it.
#pragma once

#include <cstdint>
#include <vector>

namespace avsplat::sim {

struct Mesh {
    std::vector<float> vertices;           // n x 3, as placed in the scene
    std::vector<std::uint32_t> triangles;  // m x 3
};

/// The bunny of the default scene (parsed on first use; thread-safe).
const Mesh& bunny();

}  // namespace avsplat::sim
