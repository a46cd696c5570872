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
    GaussianPlyWriter,
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
from ._avsplat import RenderWorkspace  # noqa: F401

# The keyword defaults of render() and of the fusion functions, read from the C++ structs
# (RenderOptions, FusionParams): {"render": {...}, "fusion": {...}}.
from ._avsplat import defaults  # noqa: F401,E402

from ._avsplat import (  # noqa: F401
    FeatureFusionResult,
    FeatureLayout,
    FusionStream,
    GaussianFusionResult,
    SparseVoxelGrid,
    fuse_gaussians,
    fuse_voxels,
)

# Raw head features <-> Gaussians (AnySplat's activations), for fusing raw features then decoding.
from ._avsplat import decode_gaussians, encode_gaussians  # noqa: F401,E402

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

# Leave out what a scene does not need: prune, reduce_sh (reduce/prune.h, reduce/reduce_sh.h).
from ._avsplat import PruneResult, ReduceShResult, prune, reduce_sh  # noqa: F401
# PlayCanvas SOG (.sog zip or a folder with meta.json).
from ._avsplat import read_sog, write_sog  # noqa: F401
# Reduce a scene to a budget of Gaussians (merge or voxel fusion).
from ._avsplat import SimplifyResult, simplify  # noqa: F401
# Assist-View selection and conditioning on per-view tokens.
from ._avsplat import AssistSelection, assist_objective, condition_tokens, select_assist_views  # noqa: F401

# CMake's project(VERSION), compiled into the module: one number for the CLI, Python and CMake.
from ._avsplat import __version__  # noqa: E402,F401

from .open3d_adapter import from_open3d, to_open3d, to_open3d_legacy  # noqa: E402,F401

# GaussianCloud.to_open3d() and friends, as the C++ free functions are in Python.
GaussianCloud.to_open3d = to_open3d
GaussianCloud.to_open3d_legacy = to_open3d_legacy
GaussianCloud.from_open3d = staticmethod(from_open3d)

# Niantic SPZ (read v2-4, write v4 or v3).
from ._avsplat import read_spz, read_spz_header, write_spz  # noqa: F401,E402
# Formats exchanged with web viewers and splat tools, and moving scenes between
# coordinate systems.
from ._avsplat import (  # noqa: F401,E402
    GaussianFormatInfo,
    coordinate_system_change,
    detect_gaussian_format,
    morton_order,
    read_compressed_ply,
    sh_rotation,
    transform,
    write_compressed_ply,
)
