// Reading a feed-forward model's predictions from a numpy .npz (io/npz.h): the one reader of the
// layout, used by `avsplat fuse` (in memory and streamed), the Python API and the Dask path.
//
// Arrays, by name, with L the leading shape of `points` (S, H, W) for S views of H x W pixels,
// or (N,) for a plain point set; any integer or float dtype is accepted and read as float32:
//   points      L x 3   world positions (required)
//   valid       L       optional; pixels where it is 0 / False are left out
//   confidence  L       optional; the confidence fusion reads (see --confidence-mapping)
//   colors      L x 3   optional RGB in [0, 1]
//   normals     L x 3   optional surface normals (point maps only)
// and then one of, in this order of precedence:
//   1. per-pixel Gaussians  scales L x 3 (linear), rotations L x 4 (w, x, y, z), opacities L in
//                           [0, 1], and sh L x K x 3 (K = 1, 4, 9, 16) or L x 3 (degree 0), or,
//                           without sh, colors (SH degree 0 from the colour);
//   2. raw features         features L x C: samples for fuse_voxels (feature fusion);
//   3. point maps           points and colors only: one flat Gaussian per pixel from
//                           gaussians_from_point_maps (point_maps.h), sized by the pixel footprint
//                           of `cameras` when given (one per view) and by the kNN distance otherwise.
// Other arrays are ignored. Problems (a missing or misshaped array, an incomplete Gaussian
// parameter set) throw avsplat::IOError naming the file and the array.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"

#include <string>
#include <vector>

namespace avsplat {

/// What a prediction .npz held, as samples ready for fusion.
struct PredictionSamples {
    enum class Kind { Gaussians, Features };
    Kind kind = Kind::Gaussians;
    /// Kind::Gaussians: one Gaussian per valid pixel, in pixel order, with the confidence
    /// channel when the file has one.
    GaussianCloud gaussians;
    /// Kind::Features: n x 3 positions, n x C features and n confidences (or none).
    std::vector<float> positions;
    std::vector<float> features;
    int channels = 0;
    std::vector<float> confidence;
    /// How the file was read, e.g. "per-pixel Gaussians (2 x 120 x 160, SH degree 0)".
    std::string description;

    std::size_t size() const { return kind == Kind::Gaussians ? gaussians.size() : positions.size() / 3; }
};

/// Reads the predictions in `path` (see the header comment). `cameras`: empty, or one camera
/// per view for the point-map case (their sizes must match W x H).
PredictionSamples read_prediction_npz(const std::string& path, const std::vector<Camera>& cameras = {});

/// Gaussians from a Gaussian file (.ply, .splat; io/gaussian_io.h) or a prediction .npz (cases 1
/// and 3 above; raw features are an IOError, as they are not Gaussians).
GaussianCloud read_gaussian_input(const std::string& path, const std::vector<Camera>& cameras = {});

}  // namespace avsplat
