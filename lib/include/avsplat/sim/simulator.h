// Prediction simulator: a ground-truth scene with fine detail, and the per-pixel predictions a
// feed-forward model would make of it. Part of the core library (no Open3D); the tests check the
// ray caster against Open3D's RaycastingScene distance queries. Code: lib/src/sim/ (textures,
// bunny_mesh, raycast, cameras, predictions).
//
// The default scene (world frame z up, units are "metres"):
//   Ground  the plane z = 0, x in [-3, 3], y in [-3, 1.5]: sand/brown checkerboard of 0.5 tiles
//           with dark joints, a fine 0.1 checker and fractal value noise.
//   Wall    the plane y = 1.5, x in [-3, 3], z in [0, 1.8]: bricks (0.3 x 0.12, mortar joints,
//           per-brick colour) with fractal grain.
//   Bunny   the Stanford Bunny (Stanford 3D Scanning Repository, public domain, via npm's
//           `bunny` package; scripts/convert_bunny.py), 8000 triangles, 1 wide, standing at the
//           origin and sunk 0.01 into the ground so that its base never coincides with it:
//           3D fractal noise between cream and green with fine marble stripes.
//   Sphere  centre (0.95, 0.35, 0.3), radius 0.3, intersected analytically (exact): a 16 x 8
//           latitude/longitude checker of white and blue with fine noise.
// Colour is a function of the 3D point and the object alone (`scene_color`), so a colour error
// is always a geometry error. The bunny mesh is compiled into the library (no file is read).
//
// Cameras: S views on an arc of radius 2.6 around (0.25, 0.1, 0.35), at height 1.3, azimuths
// evenly from -160 to -20 degrees (in front of the wall), looking at that point, pinhole with
// the principal point at the image centre, near 0.01, far 100. Held-out target views sit midway
// between two neighbouring input views.
//
// A prediction of pixel (s, row, col), made as a feed-forward model makes one:
//   1. the true hit: the pixel-centre ray of the true camera against the scene, in double
//      precision: the planes and the sphere exactly, the bunny's triangles through a bounding
//      volume hierarchy (Open3D's RaycastingScene::CastRays is not used: with Debian 12's
//      system Embree it reports no hits at all);
//   2. depth noise: the depth along the ray is multiplied by 1 + sigma n, n ~ N(0, 1), with
//      sigma = depth_noise * (1 + 2 (1 - |cos|)), cos between ray and normal (depth heads are
//      worse on slanted surfaces);
//   3. flying pixels (optional): a pixel with a valid 4-neighbour whose true depth differs by more
//      than 8 d / sqrt(fx fy) (a step that only a surface slanted by more than about 83 degrees
//      to the ray makes between neighbouring pixels) is also multiplied by (d + u (d_n - d)) / d,
//      u ~ U(0, 0.5), d_n the depth of the neighbour with the largest step (depth heads smear
//      depth across discontinuities). The total depth factor is floored at 0.1;
//   4. misregistration: the view's point map is unprojected with the view's predicted camera,
//      the true camera rotated about its centre by a random rotation (rms angle
//      pose_noise_rot_deg) and moved by a random translation (rms length pose_noise_trans);
//   5. colour: the mean of supersample x supersample stratified samples of the pixel in the true
//      camera (the image the model saw), the background colour where a sample hits nothing
//      (with the error models below: footprint-weighted, mixed at edges, through the view's gains);
//   6. confidence: log(0.01 d / max(e, 1e-6 d)) + confidence_noise * N(0, 1), d the true depth,
//      e = |predicted - true point|: a logit that is 0 at a 1% relative error, higher where the
//      prediction is better, correlated with the true error but not equal to it;
//   7. a normal: the true normal (facing the camera) rotated by the view's pose error.
// Pixels whose centre ray hits nothing are invalid.
//
// Error models of real predictions, each off by default (then the results above are
// bit-identical to a simulator without them) and each drawn from its own random stream, so that
// switching one on changes no other:
//   Pixel footprint (footprint_sigma, pixels): a camera pixel integrates radiance over more than
//     its square: lens blur, the optical low-pass filter and demosaicing spread it. The pixel's
//     sensitivity is its unit square convolved with an isotropic Gaussian of std footprint_sigma
//     pixels (box (x) Gaussian; 0 is the box, the area sampling of step 5). Colours are the
//     footprint-weighted mean of a supersample x supersample grid of rays per pixel, cast over
//     the footprint's support (4 sigma beyond the pixel), so the per-pixel blur on the surface
//     grows with distance and obliquity as in real images. ground_truth renders target views the
//     same way (same options), so the reference has the same optics.
//   Per-view appearance (exposure_sigma, white_balance_sigma, specular): auto-exposure and auto
//     white balance differ between the frames of a capture, so each view's colours are
//     multiplied by seeded gains: 2^(exposure_sigma n_0) on all channels and exp(white_balance_
//     sigma n_1), exp(white_balance_sigma n_2) on red and blue (green is the reference channel,
//     as in camera white balance), n ~ N(0, 1), then clipped to [0, 1] (sensor saturation);
//     the target views' ground truth has unit gains (a calibrated reference). `specular` adds a
//     view-dependent term of that strength to two materials, as real scenes have and a colour
//     per point (SH degree 0) cannot represent: a Blinn-Phong highlight on the sphere (shininess
//     50) and a sheen (1 - |n.v|)^4 at grazing views of the bunny, white light from the fixed
//     direction (-0.4, -0.6, 1) / |.|; ground and wall stay matte. ground_truth includes it for
//     the target's direction.
//   Mixed pixels (mixed_pixel_radius, pixels): feed-forward heads predict at patch resolution
//     (ViT patches of 14 pixels, upsampled by a DPT head), so attributes near depth edges mix the
//     two surfaces. A valid pixel's colour becomes (1 - beta) c + beta c_other, beta the fraction
//     of the pixels within the disc of that radius (inside the image) that lie on another surface
//     (background, or a depth step larger than the flying-pixel rule's 8 d / sqrt(fx fy)) and
//     c_other their mean colour. Its depth error is the flying-pixel model's (step 3).
//   Head features and their noise (attribute_noise): every prediction carries raw Gaussian-head
//     features (Predictions::features, the FeatureLayout of fusion/feature_decoder.h: opacity
//     logit, log scales, quaternion, SH degree 0): the pixel's Gaussian of Predictions::gaussians
//     encoded (encode_gaussians), with noise of std attribute_noise * u on each colour channel,
//     5 attribute_noise * u on the opacity logit and 2 attribute_noise * u on each log scale,
//     where u = Predictions::uncertainty is where a model is unsure, 1 + far + grazing +
//     textureless + edge: far = min(1, max(0, d / d_median - 1)) (d_median of the view's valid
//     pixels), grazing = 1 - |cos|, textureless = 1 - min(1, g / 0.1) with g the largest colour
//     step to a 4-neighbour on the same surface, edge = 1 when a pixel within 2 (Chebyshev) lies
//     on another surface; u is in [1, 5].
//   Confidence informativeness (confidence_rho, optional): the confidence's Spearman correlation
//     with the negative total error e = e_geo / (0.01 d) + e_app / 0.05 (e_geo the point error,
//     e_app the mean absolute difference between the decoded feature colour and the pixel's true
//     diffuse colour; each term is 1 at a 1 % depth error and at a 0.05 colour error). Gaussian
//     copula: z = Phi^-1 of the pixel's rank of -e, y = r z + sqrt(1 - r^2) n with
//     r = 2 sin(pi rho / 6) (the Pearson correlation whose Spearman correlation is rho), and the
//     confidences of the default model (step 6), sorted, are handed out in the order of y: the
//     confidence's distribution is unchanged, only what it knows about the error changes. The
//     opacity logit feature is the confidence (plus its noise), as the opacity of
//     Predictions::gaussians is sigmoid(confidence). Predictions::confidence_spearman reports
//     the measured Spearman correlation (whether confidence_rho is set or not). Random numbers come from one std::mt19937_64
// per view, seeded from (seed, view), with every pixel drawing the same count in row-major
// order, through transforms written out here (not std::*_distribution, which differ between
// standard libraries): results are bit-identical for a seed and any number of threads.
#pragma once

#include "avsplat/core/camera.h"
#include "avsplat/core/gaussians.h"
#include "avsplat/core/mesh.h"
#include "avsplat/fusion/feature_decoder.h"
#include "avsplat/point_maps/point_maps.h"

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace avsplat {

/// Objects of the default scene, as stored in the object_id images (int32).
enum class SceneObject : std::int32_t { Background = -1, Ground = 0, Wall = 1, Bunny = 2, Sphere = 3 };

/// The default scene's geometry (see the header comment), for callers that measure against it.
namespace default_scene {
inline constexpr double kWallY = 1.5;
inline constexpr double kWallHeight = 1.8;
inline constexpr double kGroundMinX = -3.0, kGroundMaxX = 3.0;
inline constexpr double kGroundMinY = -3.0, kGroundMaxY = kWallY;
inline constexpr std::array<double, 3> kSphereCenter{0.95, 0.35, 0.3};
inline constexpr double kSphereRadius = 0.3;
/// The bunny is the embedded mesh moved down by this much.
inline constexpr double kBunnySink = 0.01;
}  // namespace default_scene

struct SimulatorOptions {
    int views = 16;                    ///< S input views, >= 1
    int width = 128;                   ///< image width in pixels, >= 1
    int height = 96;                   ///< image height in pixels, >= 1
    double fov_y = 50.0;               ///< vertical field of view in degrees, in (0, 180)
    int target_views = 4;              ///< held-out views, 0 <= target_views <= views - 1
    double pose_noise_rot_deg = 0.2;   ///< rms rotation error of a view's pose, degrees, >= 0
    double pose_noise_trans = 0.004;   ///< rms translation error of a view's pose, >= 0
    double depth_noise = 0.004;        ///< relative depth noise (on fronto-parallel surfaces), >= 0
    bool flying_pixels = true;         ///< smear depth across discontinuities (step 3)
    double confidence_noise = 0.5;     ///< std of the noise on the confidence logit, >= 0
    int supersample = 2;               ///< colour samples per pixel side, 1..16
    /// Colour where a ray hits nothing (as the renderer's RenderOptions::background).
    std::array<float, 3> background{0.0f, 0.0f, 0.0f};
    std::uint64_t seed = 0;
    // Error models (see the header comment); the defaults switch them off.
    double footprint_sigma = 0.0;       ///< std of the optical blur in pixels, 0..8
    double exposure_sigma = 0.0;        ///< std of the per-view exposure in stops, >= 0
    double white_balance_sigma = 0.0;   ///< std of the per-view log red/blue gains, >= 0
    double specular = 0.0;              ///< strength of the view-dependent term, 0..1
    double mixed_pixel_radius = 0.0;    ///< radius of colour mixing at depth edges in pixels, 0..16
    double attribute_noise = 0.0;       ///< std of the head-feature noise at u = 1, >= 0
    /// Target Spearman correlation of the confidence with the negative total error, in [-1, 1];
    /// unset: the default confidence model (step 6).
    std::optional<double> confidence_rho;

    /// Throws std::invalid_argument naming the first field out of range.
    void validate() const;
};

/// Simulated predictions of S views of H x W pixels. Arrays are row-major, pixel (s, row, col)
/// at flat index (s * H + row) * W + col; entries of invalid pixels are 0 (colour: background).
struct Predictions {
    int views = 0;
    int height = 0;
    int width = 0;
    std::vector<float> points;       ///< S x H x W x 3 predicted world points
    std::vector<float> colors;       ///< S x H x W x 3 RGB in [0, 1]
    std::vector<float> confidence;   ///< S x H x W logit (higher = more reliable)
    std::vector<float> true_error;   ///< S x H x W distance from the predicted to the true point
    std::vector<float> true_points;  ///< S x H x W x 3 the true hit of the pixel-centre ray
    std::vector<float> normals;      ///< S x H x W x 3 predicted unit normals, facing the camera
    std::vector<std::uint8_t> valid; ///< S x H x W, 1 where the pixel-centre ray hits the scene
    std::vector<std::int32_t> object_id;  ///< S x H x W SceneObject of the true hit
    std::vector<Camera> cameras;       ///< the predicted (misregistered) cameras, which unproject
    std::vector<Camera> true_cameras;  ///< the cameras that took the views
    std::vector<Camera> target_cameras;  ///< held-out views, = target_cameras(options)
    /// S x H x W x C raw Gaussian-head features (layout `feature_layout`, C = layout.channels()),
    /// 0 for invalid pixels: the error models' "head features" (header comment).
    std::vector<float> features;
    FeatureLayout feature_layout;
    std::vector<float> uncertainty;        ///< S x H x W, u in [1, 5] (0 for invalid pixels)
    std::vector<float> appearance_error;   ///< S x H x W, e_app (0 for invalid pixels)
    std::vector<float> view_gains;         ///< S x 3 RGB gains of the per-view appearance model
    /// Spearman correlation of confidence with -(e_geo / (0.01 d) + e_app / 0.05) over the valid
    /// pixels (NaN with fewer than 2).
    double confidence_spearman = 0.0;

    /// A view of the arrays for gaussians_from_point_maps (valid only while *this lives).
    PointMaps point_maps() const;
    /// One flat Gaussian per valid pixel, in pixel order: gaussians_from_point_maps with the
    /// predicted cameras (scale from the pixel footprint) and the predicted normals; opacity and
    /// the confidence channel from `confidence`.
    GaussianCloud gaussians(const PointMapOptions& options = {}) const;
    /// One Gaussian per valid pixel, in pixel order, decoded from `features` (decode_gaussians)
    /// at the predicted points, with the confidence channel: the per-pixel Gaussians with every
    /// error model, including the attribute noise.
    GaussianCloud decoded_gaussians() const;
};

/// Simulates the predictions of options.views views of the default scene (see the header
/// comment). Throws std::invalid_argument for invalid options.
Predictions simulate_predictions(const SimulatorOptions& options = {});

/// The options.views input cameras (true poses) in arc order.
std::vector<Camera> input_cameras(const SimulatorOptions& options = {});

/// The options.target_views held-out cameras: target j sits midway between input views g_j and
/// g_j + 1, g_j = floor((j + 0.5) (S - 1) / T), so that the targets spread over the arc and
/// never coincide with an input view. Throws std::invalid_argument for invalid options.
std::vector<Camera> target_cameras(const SimulatorOptions& options = {});

/// A ground-truth render of the default scene, H x W = camera.height x camera.width, row-major.
struct GroundTruthImage {
    int width = 0;
    int height = 0;
    std::vector<float> color;   ///< H x W x 3: the mean of supersample^2 stratified samples,
                                ///< each the scene colour or, where it hits nothing, background
                                ///< (footprint-weighted over more samples when footprint_sigma > 0)
    std::vector<float> alpha;   ///< H x W: the (footprint-weighted) fraction of the samples that hit the scene
    std::vector<float> depth;   ///< H x W: camera-space z of the pixel-centre hit, 0 where none
    std::vector<float> normals; ///< H x W x 3: unit world normal of the centre hit, facing the
                                ///< camera; 0 where none
    std::vector<std::int32_t> object_id;  ///< H x W: SceneObject of the centre hit
};

/// Renders the default scene from `camera` by ray casting, with options.supersample,
/// options.background, options.footprint_sigma and options.specular (the other options are not
/// used). Throws std::invalid_argument for an
/// invalid camera or options.
GroundTruthImage ground_truth(const Camera& camera, const SimulatorOptions& options = {});

/// The ground-truth colour (RGB in [0, 1]) of a point on `object` (the procedural texture; the
/// point is not checked to lie on the object). Throws std::invalid_argument for Background.
Eigen::Vector3f scene_color(const Eigen::Vector3d& point, SceneObject object);

/// The embedded Stanford bunny as placed in the scene (world coordinates). Convert it with
/// to_open3d (avsplat/open3d/conversion.h) for Open3D.
TriangleMesh bunny_mesh();

}  // namespace avsplat
