// Reading and writing cameras as JSON.
//
// avsplat's own format (what write_cameras_json writes): a list of objects
//   {"name": "...", "fx": f, "fy": f, "cx": f, "cy": f, "width": i, "height": i,
//    "world_to_camera": [[4 x 4 row-major]], "near": f, "far": f}
// "name", "near" and "far" are optional on reading. A single object, or {"cameras": [...]},
// is read too.
//
// Read as well, where the fields map directly:
//   * 3DGS cameras.json (INRIA): a list of {"img_name", "width", "height", "position": [3],
//     "rotation": [[3 x 3]] (camera-to-world), "fx", "fy"}; principal point at the centre.
//   * nerfstudio / instant-ngp transforms.json: {"fl_x", "fl_y", "cx", "cy", "w", "h",
//     "frames": [{"file_path", "transform_matrix": camera-to-world, OpenGL axes}]}, with
//     per-frame intrinsics overriding the global ones and "camera_angle_x" accepted in place of
//     "fl_x". The OpenGL axes (y up, z back) are converted to OpenCV (y down, z forward).
// Errors (IOError) name the file and the field or the camera index that is wrong.
#pragma once

#include "avsplat/core/camera.h"

#include <string>
#include <vector>

namespace avsplat {

/// All cameras in `path`, in file order. Each camera is validated.
std::vector<Camera> read_cameras_json(const std::string& path);

/// The camera at `index` in `path` (default: the first).
Camera read_camera_json(const std::string& path, std::size_t index = 0);

/// Writes cameras in avsplat's format (a list, even for one camera).
void write_cameras_json(const std::string& path, const std::vector<Camera>& cameras);
void write_camera_json(const std::string& path, const Camera& camera);

}  // namespace avsplat
