// Open3D adapter (target avsplat::open3d, built with AVSPLAT_WITH_OPEN3D).
//
// Tensor point cloud attributes use the names of Open3D's own Gaussian-splat support:
//   positions {N,3} Float32, scale {N,3} linear, rot {N,4} (w,x,y,z), opacity {N,1} logit,
//   f_dc {N,3}, f_rest {N,K-1,3} (only when the SH degree is > 0),
//   confidence {N,1} when present, and each extra channel under its own name as {N,1}.
// The legacy point cloud is a preview: points and colours from SH degree 0
// (0.5 + C0 * f_dc, clamped to [0, 1]).
//
// Open3D's headers stay out of the core: only code that links avsplat::open3d includes this.
#pragma once

#include "avsplat/core/gaussians.h"
#include "avsplat/core/mesh.h"

#include <open3d/geometry/PointCloud.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/t/geometry/PointCloud.h>

namespace avsplat {

/// GaussianCloud -> open3d::t::geometry::PointCloud on the CPU.
open3d::t::geometry::PointCloud to_open3d(const GaussianCloud& cloud);

/// open3d::t::geometry::PointCloud -> GaussianCloud. Needs positions, scale, rot, opacity and
/// f_dc (f_rest optional); any other {N} or {N,1} float attribute becomes an extra channel
/// ("confidence" becomes the confidence). Throws std::invalid_argument naming the attribute that
/// is missing or has the wrong shape. Device tensors are copied to the CPU.
GaussianCloud from_open3d(const open3d::t::geometry::PointCloud& pcd);

/// A legacy point cloud (points + colours from SH degree 0) for previews and legacy pipelines.
open3d::geometry::PointCloud to_open3d_legacy(const GaussianCloud& cloud);

/// A legacy Open3D triangle mesh with the same vertices and triangles (e.g. the simulator's
/// bunny_mesh()). Throws std::invalid_argument for an index outside the vertices.
open3d::geometry::TriangleMesh to_open3d(const TriangleMesh& mesh);

}  // namespace avsplat
