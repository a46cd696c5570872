// Reading the cameras of a COLMAP sparse model (cameras.txt + images.txt, or cameras.bin +
// images.bin, as written by `colmap model_converter` and the mapper).
//
// Each registered image becomes one Camera named after the image: intrinsics from its camera
// (PINHOLE: fx fy cx cy; SIMPLE_PINHOLE: f cx cy), pose from the image's world-to-camera
// quaternion (qw qx qy qz, normalised) and translation (tx ty tz), in COLMAP's axes, which are
// avsplat's (OpenCV: x right, y down, z forward). Other camera models carry lens distortion the
// renderer does not model: they are refused (run `colmap image_undistorter` first).
// Errors are IOError naming the file and the line (text) or the record (binary) and field.
#pragma once

#include "avsplat/core/camera.h"

#include <string>
#include <vector>

namespace avsplat {

/// The cameras of the COLMAP model at `path`: a directory holding cameras.bin and images.bin
/// (preferred) or cameras.txt and images.txt, or the path of any one of those files (its
/// partner is taken from the same directory). Cameras are in images file order.
/// Throws IOError when a file is missing or malformed, when an image names a camera that is
/// not in the cameras file, or when a camera's model is not PINHOLE or SIMPLE_PINHOLE
/// (the message names the file, the camera id and the model).
std::vector<Camera> read_colmap_cameras(const std::string& path);

/// True when `path` is a directory holding a COLMAP model or one of its cameras/images files.
bool is_colmap_model(const std::string& path);

}  // namespace avsplat
