#!/usr/bin/env python3
"""Converts the Stanford bunny from npm's `bunny` package into lib/data/bunny.ply.

Run once by a maintainer; the result is committed and embedded into the library at build time,
so neither npm nor this script is needed to build or run avsplat.

    cd /tmp && npm install bunny          # bunny 1.0.1: positions + cells, public domain
    /usr/bin/python3 scripts/convert_bunny.py /tmp/node_modules/bunny lib/data/bunny.ply

Origin: the Stanford Bunny of the Stanford 3D Scanning Repository
(http://graphics.stanford.edu/data/3Dscanrep/), as packaged by Mikola Lysenko in the npm
package `bunny` (licence: "Public Domain").

Steps, and why:
  1. node dumps the package's `positions` and `cells` as JSON (the package is a JS module).
  2. Open3D cleans the mesh: duplicated vertices and triangles, degenerate triangles and
     unreferenced vertices would give the ray caster zero-area hits and PCA normals nothing
     to work with.
  3. One Loop subdivision followed by quadric decimation to TARGET_TRIANGLES: the npm mesh is
     a coarse 3.7k-triangle reconstruction; subdividing smooths its facets (the simulator's
     flat Gaussians follow the surface normal) and decimating brings it back to a small file.
  4. The bunny is rotated from its y-up frame to avsplat's z-up scene frame, scaled so that
     the largest side of its bounding box is 1, centred on x and y, and set on z = 0.
  5. The mesh is written as binary little-endian PLY with exactly the layout the library's
     embedded reader expects (float x, y, z; uchar-counted int triangle indices).
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np
import open3d as o3d

TARGET_TRIANGLES = 8000


def load_npm_bunny(package_dir):
    script = (
        "const b = require(process.argv[1]);"
        "process.stdout.write(JSON.stringify({positions: b.positions, cells: b.cells}));"
    )
    out = subprocess.run(["node", "-e", script, os.path.abspath(package_dir)],
                         check=True, capture_output=True, text=True).stdout
    data = json.loads(out)
    return np.asarray(data["positions"], np.float64), np.asarray(data["cells"], np.int64)


def clean(mesh):
    mesh.remove_duplicated_vertices()
    mesh.remove_duplicated_triangles()
    mesh.remove_degenerate_triangles()
    mesh.remove_unreferenced_vertices()
    return mesh


def normalise(vertices):
    # y-up -> z-up: a rotation of +90 degrees about x, (x, y, z) -> (x, -z, y).
    v = np.stack([vertices[:, 0], -vertices[:, 2], vertices[:, 1]], axis=1)
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])) / (hi - lo).max()
    return v


def write_ply(path, vertices, triangles):
    header = (
        "ply\n"
        "format binary_little_endian 1.0\n"
        "comment Stanford Bunny, Stanford 3D Scanning Repository, via npm package 'bunny' "
        "(public domain)\n"
        "comment converted by scripts/convert_bunny.py: z up, largest side 1, base on z = 0\n"
        f"element vertex {len(vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(triangles)}\n"
        "property list uchar int vertex_indices\n"
        "end_header\n"
    )
    faces = np.zeros(len(triangles), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = triangles
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vertices.astype("<f4").tobytes())
        f.write(faces.tobytes())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("package_dir", help="node_modules/bunny of `npm install bunny`")
    parser.add_argument("output", help="the PLY to write, e.g. lib/data/bunny.ply")
    args = parser.parse_args()

    positions, cells = load_npm_bunny(args.package_dir)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(positions),
                                     o3d.utility.Vector3iVector(cells.astype(np.int32)))
    mesh = clean(mesh)
    print(f"npm bunny: {len(positions)} vertices, {len(cells)} triangles; "
          f"cleaned: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles")
    mesh = mesh.subdivide_loop(number_of_iterations=1)
    mesh = clean(mesh.simplify_quadric_decimation(TARGET_TRIANGLES))
    vertices = normalise(np.asarray(mesh.vertices))
    triangles = np.asarray(mesh.triangles, np.int32)
    write_ply(args.output, vertices, triangles)
    print(f"wrote {args.output}: {len(vertices)} vertices, {len(triangles)} triangles, "
          f"{os.path.getsize(args.output)} bytes, extent {np.ptp(vertices, axis=0).round(4)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
