// A triangle mesh in plain arrays: the geometry a scene's reference surface comes as (the
// simulator's bunny, a scan) and what the Open3D adapter converts.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat {

/// V x 3 vertex positions and F x 3 vertex indices (each < V), row-major.
struct TriangleMesh {
    std::vector<double> vertices;
    std::vector<std::int32_t> triangles;
    std::size_t num_vertices() const noexcept { return vertices.size() / 3; }
    std::size_t num_triangles() const noexcept { return triangles.size() / 3; }
};

}  // namespace avsplat
