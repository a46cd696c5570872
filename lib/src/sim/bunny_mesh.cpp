#include "sim/bunny_mesh.h"

#include "avsplat/io/ply_data.h"
#include "avsplat/sim/simulator.h"

#include <stdexcept>
#include <string>

namespace avsplat {

namespace embedded {
// lib/data/bunny.ply, compiled in by lib/cmake/embed_file.cmake.
extern const unsigned char bunny_ply[];
extern const std::size_t bunny_ply_size;
}  // namespace embedded

namespace sim {

namespace {

// ---------------------------------------------------------------------------------------------
// The embedded bunny (lib/data/bunny.ply, as scripts/convert_bunny.py writes it), read with the
// generic PLY layer. A file without a triangle mesh means a wrong file was embedded, which is a
// build error, not bad input.

Mesh parse_bunny() {
    auto fail = [](const std::string& what) {
        throw std::logic_error("embedded bunny.ply: " + what + " (rebuild from lib/data/bunny.ply)");
    };
    const PlyData ply = parse_ply_data(embedded::bunny_ply, embedded::bunny_ply_size, "embedded bunny.ply");
    const PlyElement* vertex = ply.find("vertex");
    const PlyElement* face = ply.find("face");
    if (!vertex || !face) fail("no vertex or face element");
    const PlyColumn* xyz[3] = {vertex->find("x"), vertex->find("y"), vertex->find("z")};
    const PlyColumn* indices = face->find("vertex_indices");
    if (!xyz[0] || !xyz[1] || !xyz[2] || !indices || !indices->is_list) fail("no x, y, z or vertex_indices");
    const std::size_t n = static_cast<std::size_t>(vertex->count);
    const std::size_t m = static_cast<std::size_t>(face->count);
    Mesh mesh;
    mesh.vertices.resize(3 * n);
    for (std::size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) mesh.vertices[3 * i + a] = static_cast<float>(xyz[a]->values[i]);
    mesh.triangles.resize(3 * m);
    for (std::size_t f = 0; f < m; ++f) {
        if (indices->offsets[f + 1] - indices->offsets[f] != 3) fail("a face is not a triangle");
        for (int c = 0; c < 3; ++c) {
            const double v = indices->values[indices->offsets[f] + c];
            if (!(v >= 0 && v < double(n))) fail("a vertex index is out of range");
            mesh.triangles[3 * f + c] = static_cast<std::uint32_t>(v);
        }
    }
    for (std::size_t i = 0; i < n; ++i) mesh.vertices[3 * i + 2] -= static_cast<float>(default_scene::kBunnySink);
    return mesh;
}

}  // namespace

const Mesh& bunny() {
    static const Mesh mesh = parse_bunny();  // parsed once, thread-safe initialisation
    return mesh;
}

}  // namespace sim

TriangleMesh bunny_mesh() {
    const sim::Mesh& b = sim::bunny();
    TriangleMesh mesh;
    mesh.vertices.assign(b.vertices.begin(), b.vertices.end());
    mesh.triangles.assign(b.triangles.begin(), b.triangles.end());
    return mesh;
}

}  // namespace avsplat
