"""avsplat: the geometry side of feed-forward 3D Gaussian Splatting.

Fuse per-pixel Gaussian predictions with occupancy-guided voxel fusion, render them, measure
them and export them. The names mirror the C++ API (``avsplat::GaussianCloud`` ->
``avsplat.GaussianCloud``); arrays go in and out as numpy float32 with the shapes given in each
docstring.
"""

from ._avsplat import (  # noqa: F401
    Camera,
    DeviceError,
    GaussianCloud,
    IOError,
    SanitizeReport,
    concatenate,
    read_camera_json,
    read_cameras_json,
    read_gaussians,
    read_ply,
    read_ply_data,
    read_splat,
    sh_degree_for_coeffs,
    write_camera_json,
    write_cameras_json,
    write_gaussians,
    write_ply,
    write_splat,
)

from ._avsplat import (  # noqa: F401
    AccuracyCompleteness,
    accuracy_completeness,
    chamfer_distance,
    compute_point_cloud_distance,
    gaussians_from_point_maps,
    remove_statistical_outliers,
)

from ._avsplat import RenderResult, RenderStats, cuda_device_count, psnr, render, ssim  # noqa: F401

# The keyword defaults of render() and of the fusion functions, read from the C++ structs
# (RenderOptions, FusionParams): {"render": {...}, "fusion": {...}}.
from ._avsplat import defaults  # noqa: F401,E402

from ._avsplat import (  # noqa: F401
    FeatureFusionResult,
    FusionStream,
    GaussianFusionResult,
    SparseVoxelGrid,
    fuse_gaussians,
    fuse_voxels,
)

from ._avsplat import turbo_colormap, write_alpha_png, write_color_png, write_depth_png  # noqa: F401

from ._avsplat import (  # noqa: F401
    GroundTruthImage,
    Predictions,
    SceneObject,
    bunny_mesh,
    ground_truth,
    input_cameras,
    scene_color,
    simulate_predictions,
    target_cameras,
)

# Greedy coverage on point maps (the geometry side of Assist-View selection).
from ._avsplat import ViewCoverage, select_views_by_coverage  # noqa: F401

# Assist-View selection and conditioning on per-view tokens.
from ._avsplat import AssistSelection, assist_objective, condition_tokens, select_assist_views  # noqa: F401

__version__ = "0.1.0"

from .open3d_adapter import from_open3d, to_open3d, to_open3d_legacy  # noqa: E402,F401

# GaussianCloud.to_open3d() and friends, as the C++ free functions are in Python.
GaussianCloud.to_open3d = to_open3d
GaussianCloud.to_open3d_legacy = to_open3d_legacy
GaussianCloud.from_open3d = staticmethod(from_open3d)
