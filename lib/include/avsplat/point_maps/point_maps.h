// Point maps -> Gaussians.
//
// Many feed-forward models (VGGT, DUSt3R-style heads) predict only a point map, a colour and a
// confidence per pixel. `gaussians_from_point_maps` turns such predictions into one flat
// Gaussian per pixel: the scale comes from the pixel footprint when the cameras are known, or
// else from the distance to the nearest neighbours (as the 3DGS reference code initialises
// Gaussians from SfM points); the Gaussian lies flat along the surface (the given normal, or the
// local PCA normal); the opacity comes from the confidence.
//
// Neighbour searches use a nanoflann KD-tree. Every function here is deterministic and its
// result does not depend on the number of OpenMP threads.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/confidence.h"
#include "avsplat/core/gaussians.h"

#include <cstddef>
#include <cstdint>
#include <vector>

namespace avsplat {

/// Per-pixel predictions of S views of H x W pixels: contiguous row-major float32 arrays owned
/// by the caller (nothing is copied). Pixel (s, row, col) has the flat index
/// (s * H + row) * W + col. Data without an image layout (a plain point set of N points) is
/// views = 1, height = 1, width = N.
struct PointMaps {
    int views = 0;
    int height = 0;
    int width = 0;
    const float* points = nullptr;        ///< S x H x W x 3 world positions (required)
    const float* colors = nullptr;        ///< S x H x W x 3 RGB, nominally in [0, 1] (required)
    const float* confidence = nullptr;    ///< S x H x W, or null: no confidence
    /// S x H x W x 3 surface normals (any non-zero length, either sign), or null: estimate
    /// them by PCA of the nearest points.
    const float* normals = nullptr;
    /// S x H x W, non-zero where the pixel holds a prediction, or null: every pixel does.
    const std::uint8_t* valid = nullptr;

    /// S * H * W.
    std::size_t pixels() const noexcept {
        return static_cast<std::size_t>(views) * static_cast<std::size_t>(height) *
               static_cast<std::size_t>(width);
    }
};

struct PointMapOptions {
    /// Without cameras: the in-plane scale is the root mean square distance to the k nearest
    /// other points (3DGS initialises with k = 3). Must be >= 1.
    int k = 3;
    /// Points (the point itself included) whose PCA gives the normal when no normals are
    /// given. Must be >= 3.
    int normal_neighbors = 16;
    /// true: flat Gaussians along the surface; false: isotropic Gaussians (identity rotation,
    /// no normals needed or estimated).
    bool flat = true;
    /// Scale along the normal as a fraction of the in-plane scale, in (0, 1].
    double thickness = 0.1;
    /// Multiplies the in-plane scale (the kNN distance, or the pixel footprint). The default 0.5
    /// makes the 1-sigma ellipse span the pixel's footprint (with kNN: reach halfway to the
    /// neighbours), which renders sharp and without holes; 1 is the 3DGS initialisation, whose
    /// blur its optimisation then removes. Must be > 0.
    double scale_multiplier = 0.5;
    /// With cameras, a flat Gaussian is stretched by 1 / |cos(angle between ray and normal)|
    /// along the tangent direction of the viewing ray, so that it covers the pixel's footprint
    /// on a slanted surface; the stretch is capped here (>= 1) so that grazing pixels do not
    /// become long streaks.
    double max_stretch = 4.0;
    /// Lower bound on every axis length, so that duplicated points never yield a zero scale
    /// (whose logarithm, the 3DGS PLY encoding, is -inf). Must be >= 0.
    double min_scale = 1e-7;
    /// How a confidence c becomes the opacity: the probability q of the mapping
    /// (fusion_weights.h; Logit: sigmoid(c), Probability: c, Positive: c / (1 + c)), the same
    /// reading of the confidence that fusion uses.
    ConfidenceMapping confidence_mapping = ConfidenceMapping::Logit;
    /// Opacity of every Gaussian when the point maps carry no confidence, in [0, 1].
    double default_opacity = 1.0;
};

/// One Gaussian per valid pixel, in pixel order (view, row, column), with SH degree 0 from the
/// colour, the raw confidence as the cloud's confidence channel (when given), and:
///
///   in-plane scale s  with cameras: scale_multiplier * z / sqrt(fx * fy), z the point's depth
///                     in its view's camera (the pixel footprint); without: scale_multiplier *
///                     the RMS distance to the k nearest other valid points (all of them when
///                     fewer).
///   orientation       flat: local z axis along the normal (given, or the PCA normal of the
///                     normal_neighbors nearest valid points; with cameras it faces the
///                     camera), axes s (x stretch with cameras, see max_stretch), s,
///                     thickness * s; not flat: identity, s on all axes. Every axis >= min_scale.
///   opacity           the confidence's probability q (PointMapOptions::confidence_mapping),
///                     else default_opacity.
///
/// `cameras`: empty (kNN scale), or one camera per view whose width and height equal the point
/// maps' (the camera that took the view; its pose places the footprint).
///
/// Throws std::invalid_argument, naming the field and the first bad flat index with its
/// (view, row, col), for: negative dimensions; a missing points/colors array; an option out of
/// range; a camera count or size mismatch or an invalid camera; a non-finite point, colour,
/// confidence or normal in a valid pixel; a zero normal; a confidence outside its mapping's
/// domain; a valid point at or behind its camera (z <= 0); fewer than 2 valid points when the
/// kNN scale is needed. No valid pixel gives an empty cloud.
GaussianCloud gaussians_from_point_maps(const PointMaps& maps,
                                        const std::vector<Camera>& cameras = {},
                                        const PointMapOptions& options = {});

}  // namespace avsplat
